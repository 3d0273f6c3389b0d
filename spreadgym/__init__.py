"""spreadgym: a validated plan-view simulator of centrifugal fertilizer spreaders.

The core (this package's own modules) imports no gymnasium. The Gymnasium environments
of the envs layer are registered as soon as both `spreadgym` and `gymnasium` are
imported, in either order, without this package importing gymnasium itself: a command
that makes no env (`spreadgym simulate`) does not pay for it. That hook, and the console
script in the agents layer, are the only places where the layers meet, and they only
point upwards by name (entry-point strings).
"""

import importlib.abc
import sys

__version__ = "0.1.0"


def _register_envs() -> None:
    from spreadgym.envs.registration import register_envs

    register_envs()


class _RegisterAfterGymnasium(importlib.abc.MetaPathFinder):
    """Import hook, used once: when `gymnasium` is first imported, register the envs right
    after its module has run (so `import spreadgym; import gymnasium; gym.make("spreadgym/...")`
    works as it did when this package imported gymnasium eagerly)."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        sys.meta_path.remove(self)
        from importlib.util import find_spec

        spec = find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        run_module = spec.loader.exec_module

        def exec_then_register(module):
            run_module(module)
            _register_envs()

        spec.loader.exec_module = exec_then_register
        return spec


if "gymnasium" not in sys.modules:
    sys.meta_path.insert(0, _RegisterAfterGymnasium())
elif sys.modules["gymnasium"] is not None:  # None: blocked on purpose (the core runs without it)
    _register_envs()
