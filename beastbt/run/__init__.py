"""One run of a mission: the tick loop, failsafes, the session that paces it, the run summary."""
