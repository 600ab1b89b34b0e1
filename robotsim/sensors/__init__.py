"""Simulated sensors: wheel encoders, gyro and accelerometer, the sonar belt."""
