"""What is computed from camera images: the camera model and the line detector."""
