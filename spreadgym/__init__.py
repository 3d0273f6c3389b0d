"""spreadgym: a validated plan-view simulator of centrifugal fertilizer spreaders.

The core (this package's own modules) imports no gymnasium. Importing the package
registers the Gymnasium environments of the envs layer when gymnasium is installed:
that hook, and the console script in the agents layer, are the only places where the
layers meet, and they only point upwards by name (entry-point strings).
"""

__version__ = "0.1.0"


def _register_envs() -> None:
    try:
        import gymnasium  # noqa: F401
    except ImportError:  # core used on its own
        return
    from spreadgym.envs.registration import register_envs

    register_envs()


_register_envs()
