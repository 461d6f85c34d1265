"""The catalogue of blackboard keys (name, type, unit, frame), the stamped reading types, and staleness checks."""
