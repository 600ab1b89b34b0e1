"""localization: Gaussian beliefs, the Kalman filter family and the motion models of the papers.

Imports none of the other testbed packages; works on numpy arrays with a leading batch axis.
"""
