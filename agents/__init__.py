"""Agents layer: SB3 training, evaluation of spread patterns, classical baselines.

Depends on spreadgym.envs and the spreadgym core, never the other way round.
"""
