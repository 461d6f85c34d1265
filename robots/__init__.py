"""Robot profiles (which devices on which ports, geometry, limits), shipped as package data."""
