"""Drivers that speak to real hardware through serial, SMBus, CAN and frame interfaces: GPS, IMU, servos, bases, camera, joystick."""
