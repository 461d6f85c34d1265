"""Saved maps (map_server YAML and PGM), shipped as package data: ``map: office`` names one."""
