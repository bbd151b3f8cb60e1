"""Simulation of the controlled robot in MuJoCo."""
