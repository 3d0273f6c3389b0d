"""YAML data shipped with spreadgym: materials, scenes, env and agent configs."""
