"""One run of a mission: the tick loop, the safety wired around every run's base, failsafes, the session that paces the loop, the run summary and the run folder."""
