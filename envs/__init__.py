"""Gymnasium layer of spreadgym (installed as spreadgym.envs)."""
