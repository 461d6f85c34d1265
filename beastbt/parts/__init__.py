"""The parts a robot is assembled from: each ties a driver, its emulator, its estimator hooks, its mission steps and its summary together. The composition root lists them."""
