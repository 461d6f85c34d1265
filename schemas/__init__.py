"""The JSON Schemas of beastbt files (missions, robot profiles, worlds, run summaries), shipped as package data."""
