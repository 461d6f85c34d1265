"""Leaf behaviours (actions and conditions) and the flow constructs py_trees lacks; one small class each, clock injected."""
