"""Nonlinear model of one actuator channel: servo valve, actuator, load and sensors."""
