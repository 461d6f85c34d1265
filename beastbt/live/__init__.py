"""What a run shows while it runs: the live video stream."""
