"""Registration of spreadgym's environments with gymnasium (called on `import spreadgym`).

Entry points are strings, so registering imports no environment module. Each env is
registered under the namespaced id `spreadgym/NAME-v0` and, so that
`gym.make("spreadgym:NAME-v0")` works (gymnasium looks the part after the colon up
as an id), under `NAME-v0` as well.
"""

from __future__ import annotations

import gymnasium

ENVS = {
    "SpinnerDesign-v0": "spreadgym.envs.spinner_design:SpinnerDesignEnv",
    "SpreaderTuning-v0": "spreadgym.envs.spreader_tuning:SpreaderTuningEnv",
}


def register_envs() -> None:
    for name, entry_point in ENVS.items():
        for env_id in (f"spreadgym/{name}", name):
            if env_id not in gymnasium.registry:
                gymnasium.register(id=env_id, entry_point=entry_point)
