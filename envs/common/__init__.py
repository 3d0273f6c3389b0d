"""What the environments share: the task (job, encoding, tray test), the base env class,
actions, reward, config and the rendered frame."""
