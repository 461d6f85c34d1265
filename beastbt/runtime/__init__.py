"""Clocks, the tick loop, robot assembly (real and simulated), failsafes, events, the run summary and run folders."""
