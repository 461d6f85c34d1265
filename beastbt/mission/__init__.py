"""Mission files: YAML loading with source positions, units, schema validation, the mission model, and compilation to a py_trees tree."""
