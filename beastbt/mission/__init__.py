"""Mission files: the mission model (loading, the checks a schema cannot make) and the compiler from a mission to a py_trees tree."""
