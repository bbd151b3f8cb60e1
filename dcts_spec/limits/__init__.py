"""Limits: joint and Cartesian bounds shaped into acceleration bounds, torque bounds."""
