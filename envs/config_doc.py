"""Print docs/config-keys.md: every key of scenes and of both environments' configs,
with its type, default and accepted range, generated from the schemas."""

from spreadgym.config.scene import Scene
from spreadgym.config.schema_doc import schema_markdown
from spreadgym.envs.common.config import DesignConfig, TuningConfig

SECTIONS = {"Scenes (configs/scenes/*.yaml, `--set`)": Scene,
            "SpinnerDesign-v0 (configs/envs/spinner_design.yaml, gym.make kwargs)": DesignConfig,
            "SpreaderTuning-v0 (configs/envs/spreader_tuning.yaml, gym.make kwargs)": TuningConfig}


def config_keys_markdown() -> str:
    return schema_markdown(SECTIONS)


if __name__ == "__main__":
    print(config_keys_markdown(), end="")
