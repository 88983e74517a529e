"""The one error every part of the configuration raises."""


class ConfigError(ValueError):
    """A configuration that cannot be used; the message names the key and the bad value."""
