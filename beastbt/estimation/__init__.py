"""State estimation: dead reckoning, the EKF, and WGS84 geodesy (latitude/longitude to local east-north-up)."""
