"""Road-vehicle reference drives and their sensors (paper 001's experiment, simulated).

- :mod:`robotsim.vehicle.single_track`: the kinematic single-track model and the
  :class:`ReferenceDrive` record (the exact reference trajectory);
- :mod:`robotsim.vehicle.drives`: the urban and highway drives, reproducible by seed;
- :mod:`robotsim.vehicle.sensors`: GPS positions and odometry (speed, yaw rate) with
  declared noise and biases, batched over Monte Carlo runs.
"""
