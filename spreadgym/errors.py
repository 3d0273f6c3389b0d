"""Errors raised for bad input: each names the key or value and what is allowed."""


class SpreadgymError(ValueError):
    """Bad input (config, CLI flag, action). The CLI prints it and exits with status 2."""


class ConfigError(SpreadgymError):
    """A config key is missing, unknown or out of range."""

    def __init__(self, key: str, message: str):
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}")

    def __reduce__(self):  # so the error crosses process boundaries (worker pools) intact, notes included
        return type(self), (self.key, self.message), self.__dict__


class MaterialError(SpreadgymError):
    """A fertilizer, surface or fertilizer-surface pair is not in the material library."""
