"""The training run config: a pydantic model per algorithm, changed by the one dotted-override function."""

import pytest

from spreadgym.agents.run_config import default_config_path, read_config, run_config_schema, validate_config
from spreadgym.config.overrides import apply_overrides
from spreadgym.errors import ConfigError


@pytest.fixture(params=["ppo", "sac"])
def algo(request):
    return request.param


def test_shipped_configs_validate_and_round_trip(algo):
    cfg = validate_config(algo, read_config(default_config_path(algo)), "shipped")
    assert cfg.algo == algo and cfg.env == "spreadgym:SpinnerDesign-v0" and cfg.normalize_kwargs is None
    assert cfg.hyperparams["learning_rate"] == 1e-3 and "policy" not in cfg.hyperparams
    assert validate_config(algo, cfg.as_yaml(), "again") == cfg
    assert cfg.replace(n_timesteps=5).n_timesteps == 5 and cfg.replace(n_timesteps=5).hyperparams == cfg.hyperparams


def test_overrides_follow_the_schema(algo):
    raw = read_config(default_config_path(algo))
    schema = run_config_schema(algo)
    with pytest.raises(ConfigError) as err:
        apply_overrides(raw, {"learning_rat": 1e-3}, schema)
    assert err.value.key == "learning_rat" and "learning_rate" in err.value.message
    with pytest.raises(ConfigError, match="^normalize: is not a section; set it as a whole$"):
        apply_overrides(raw, {"normalize.norm_obs": True}, schema)  # false is not turned into a mapping
    changes = {"normalize": {"norm_obs": True}, "env_kwargs.reward.cv_weight": 2.0}
    changed = validate_config(algo, apply_overrides(raw, changes, schema), "x")
    assert changed.normalize_kwargs == {"norm_obs": True}
    assert changed.env_kwargs == {"granules": 1000, "reward.cv_weight": 2.0}  # gym.make takes dotted keys


@pytest.mark.parametrize("change, message", [
    ({"n_envs": 0}, "n_envs: Input should be greater than or equal to 1 (got 0); allowed: >= 1"),
    ({"learning_rate": "fast"}, "learning_rate: expected a number or lin_<number>, got 'fast'"),
    ({"policy_kwargs": {"activation_fn": "sigmoid"}}, "policy_kwargs.activation_fn: unknown 'sigmoid'"),
    ({"env": "Foo-v0"}, "env: unknown environment id 'Foo-v0'"),
    ({"policy_kwargs": {"net_arch": [-1]}}, "policy_kwargs.net_arch: expected a list of at most 16 layer widths"),
    ({"policy_kwargs": {"net_arch": {"pi": [64], "vf": [10**9]}}}, "policy_kwargs.net_arch.vf: expected a list"),
    ({"policy_kwargs": {"net_arch": {"actor": [64]}}}, "policy_kwargs.net_arch.actor: unknown network"),
    ({"normalize": {"clip": 1.0}}, "normalize.clip: unknown key"),
    ({"max_minutes": -1}, "max_minutes: Input should be greater than 0 (got -1)"),
    ({"learnin_rate": 1.0}, "learnin_rate: unknown key in cfg.yaml (did you mean learning_rate?)"),
])
def test_bad_values_are_one_line_errors_naming_the_key(change, message):
    raw = read_config(default_config_path("ppo"))
    with pytest.raises(ConfigError) as err:
        validate_config("ppo", {**raw, **change}, "cfg.yaml")
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_null_means_the_default_and_a_config_names_its_algorithm():
    raw = read_config(default_config_path("ppo"))
    cfg = validate_config("ppo", {**raw, "seed": None, "normalize": None, "env_kwargs": None}, "x")
    assert cfg.seed == 0 and cfg.normalize_kwargs is None and cfg.env_kwargs == {}
    assert validate_config("ppo", {**raw, "normalize": True}, "x").as_yaml()["normalize"] is True
    with pytest.raises(ConfigError, match="^algo: x is a config for 'sac', not for 'ppo'$"):
        validate_config("ppo", {**raw, "algo": "sac"}, "x")


def test_zoo_files_hold_the_train_configs_values_for_spinner_design(algo):
    """The SpinnerDesign entries of the shipped zoo files are `spreadgym train`'s config
    without the run keys zoo takes from its command line: one set of tuned values."""
    import yaml

    from spreadgym.envs.zoo import hyperparams_path

    train = read_config(default_config_path(algo))
    zoo_file = yaml.safe_load(hyperparams_path(algo).read_text(encoding="utf-8"))
    for env_id in ("spreadgym:SpinnerDesign-v0", "spreadgym/SpinnerDesign-v0"):
        entry = dict(zoo_file[env_id])
        kwargs = entry.pop("policy_kwargs", "dict()")
        assert kwargs.startswith("dict(") and eval(kwargs, {"dict": dict}) == train.get("policy_kwargs", {})
        assert entry.pop("policy") == train["policy"]
        run_keys = {"env", "seed", "checkpoint_freq", "max_minutes"}
        assert entry == {k: v for k, v in train.items() if k not in run_keys | {"policy", "policy_kwargs"}}
