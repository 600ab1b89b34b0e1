"""The online localiser: fed a run's samples one by one, it computes exactly what the pipeline
computes on the finished arrays (bit for bit), and refuses samples out of order."""

from __future__ import annotations

import numpy as np
import pytest

from localization.dead_reckoning import (
    DeadReckoning,
    initial_belief,
    odometry_data,
    odometry_inputs,
)
from localization.errors import EstimationError
from localization.localizer import FUSED, UKF_ONLY
from scenarios.pipeline import (
    START_POSE_STD,
    dead_reckoning_noise,
    estimate,
    estimate_offline,
    localizer_for,
    scan_samples,
)
from scenarios.runner import simulate_spec
from scenarios.spec import load_scenario

pytestmark = pytest.mark.slow  # end-to-end runs compared bit for bit with the offline pipeline


def hall(seed: int, duration_s: float = 60.0):
    spec = load_scenario("hall").with_run(seed=seed, duration_s=duration_s)
    return spec, simulate_spec(spec)


def assert_same_estimation(online, offline):
    for name in ("pose", "pose_cov", "epoch_index", "before", "after", "fused_box", "component"):
        np.testing.assert_array_equal(getattr(online, name), getattr(offline, name), err_msg=name)
    for name in ("t_s", "status", "q_used", "box_counts", "boxes", "labels", "contains_truth"):
        np.testing.assert_array_equal(
            getattr(online.epochs, name), getattr(offline.epochs, name), err_msg=name
        )


@pytest.mark.parametrize("seed", [0, 3])
def test_sample_by_sample_equals_the_offline_pipeline_bit_for_bit(seed):
    spec, log = hall(seed)
    offline, _ = estimate_offline(spec, log)
    localizer = localizer_for(spec)
    at_sample = scan_samples(log)
    scan = 0
    for k in range(len(log.t_s)):
        localizer.push_odometry(
            log.t_s[k], log.wheel_ticks[k], log.gyro_rad_s[k], log.accel_m_s2[k]
        )
        if k % 37 == 0:  # asking for the estimate between scans changes nothing
            now = localizer.estimate()
            assert now.sample == k and now.pose.shape == (2, 3) and now.pose_cov.shape == (2, 3, 3)
            for branch in (UKF_ONLY, FUSED):  # the controller's read: the same mean pose
                assert localizer.pose(branch) == tuple(now.pose[branch].tolist())
        while scan < len(at_sample) and at_sample[scan] == k:
            record = localizer.push_scan(log.sonar_t_s[scan], log.sonar_range_m[scan])
            assert record is not None and record.sample == k
            assert localizer.status == record.result.status
            assert localizer.last_set is record.result.paving
            scan += 1
    history = localizer.history
    np.testing.assert_array_equal(history.mean[:, :, :3].swapaxes(0, 1), offline.pose)
    np.testing.assert_array_equal(history.pose_cov.swapaxes(0, 1), offline.pose_cov)
    last = localizer.estimate()
    np.testing.assert_array_equal(last.pose, offline.pose[:, -1])
    records = localizer.epochs
    np.testing.assert_array_equal([r.after for r in records], offline.after)
    np.testing.assert_array_equal([r.component for r in records], offline.component)
    assert offline.component.max() >= 0  # the fusion took part
    assert not np.array_equal(offline.pose[UKF_ONLY], offline.pose[FUSED])


@pytest.mark.parametrize("seed", [1, 2])
def test_the_pipeline_block_by_block_equals_the_offline_pipeline(seed):
    spec, log = hall(seed)
    online, _ = estimate(spec, log)
    offline, _ = estimate_offline(spec, log)
    assert_same_estimation(online, offline)


def test_an_interval_rate_below_the_sonar_rate_takes_every_stride_th_scan():
    spec, log = hall(0, duration_s=20.0)
    spec = spec.with_estimation(interval_rate_hz=spec.sensors.sonar.rate_hz / 3)
    online, _ = estimate(spec, log)
    offline, _ = estimate_offline(spec, log)
    assert_same_estimation(online, offline)
    np.testing.assert_array_equal(online.epochs.t_s, log.sonar_t_s[::3])


def test_extending_the_dead_reckoning_in_stretches_equals_one_run():
    spec, log = hall(4, duration_s=10.0)
    noise = dead_reckoning_noise(spec)
    localizer = localizer_for(spec)
    args = (log.wheel_ticks, log.gyro_rad_s, log.accel_m_s2, 1.0 / log.rate_hz)
    whole = odometry_data(*args, localizer.robot, noise)
    start = initial_belief(spec.start_pose, START_POSE_STD, noise)
    one = DeadReckoning(whole, start)
    one.run(whole.count - 1)
    grown = DeadReckoning(
        odometry_data(*(a[:1] for a in args[:3]), args[3], localizer.robot, noise), start
    )
    for begin, end in ((1, 2), (2, 7), (7, 400), (400, whole.count)):
        more = odometry_data(
            *(a[begin - 1 : end] for a in args[:3]), args[3], localizer.robot, noise
        )
        grown.extend(
            type(more)(
                more.dt_s, more.accel_input_m_s2[1:], more.z[1:], more.wheel_base_m, more.R, more.Q
            )
        )
        grown.run(end - 1)
    np.testing.assert_array_equal(grown.history.mean, one.history.mean)
    np.testing.assert_array_equal(grown.history.cov, one.history.cov)
    # the localiser's way: the inputs of each stretch appended, the pose read without a belief
    appended = DeadReckoning(
        odometry_data(*(a[:1] for a in args[:3]), args[3], localizer.robot, noise), start
    )
    for begin, end in ((1, 3), (3, 40), (40, 41), (41, whole.count)):
        accel_input, z = odometry_inputs(
            *(a[begin - 1 : end] for a in args[:3]), args[3], localizer.robot
        )
        appended.append_inputs(accel_input[1:], z[1:])
        appended.advance(end - 1)
        assert appended.count == end and appended.data.count == end
        for row in (UKF_ONLY, FUSED):
            assert appended.mean_pose(row) == tuple(appended.belief.mean[row, :3].tolist())
    np.testing.assert_array_equal(appended.history.mean, one.history.mean)
    np.testing.assert_array_equal(appended.history.cov, one.history.cov)
    np.testing.assert_array_equal(appended.data.z, whole.z)
    with pytest.raises(EstimationError, match="period"):
        grown.extend(odometry_data(*(a[:2] for a in args[:3]), 0.02, localizer.robot, noise))


def test_samples_out_of_order_are_refused():
    spec, log = hall(0, duration_s=2.0)
    localizer = localizer_for(spec)
    with pytest.raises(EstimationError, match="must follow the odometry sample"):
        localizer.push_scan(0.0, log.sonar_range_m[0])
    localizer.push_odometry(0.0, [0, 0], 0.0, [0.0, 0.0])
    with pytest.raises(EstimationError, match="off the 100 Hz grid"):
        localizer.push_odometry(0.03, [0, 0], 0.0, [0.0, 0.0])
    with pytest.raises(EstimationError, match="ticks must be integers"):
        localizer.push_odometry(0.01, [0.5, 0], 0.0, [0.0, 0.0])
    with pytest.raises(EstimationError, match="readings must have shape"):
        localizer.push_scan(0.0, log.sonar_range_m[0][:3])
    localizer.push_odometry(0.01, [0, 0], 0.0, [0.0, 0.0])
    with pytest.raises(EstimationError, match="must follow the odometry sample"):
        localizer.push_scan(0.0, log.sonar_range_m[0])  # a scan late by one sample
    assert localizer.status is None and localizer.last_set is None
