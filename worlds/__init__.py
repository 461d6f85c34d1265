"""Simulated worlds, shipped as package data."""
