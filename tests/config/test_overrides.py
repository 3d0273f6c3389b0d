"""The one dotted-override function: it follows the schema, and a key the schema lacks is an error."""

from typing import Any, Optional

import pytest

from spreadgym.config.base import StrictModel
from spreadgym.config.overrides import apply_overrides
from spreadgym.config.scene import Scene, load_scene, load_scene_dict
from spreadgym.errors import ConfigError


class Inner(StrictModel):
    a: float = 1.0
    b: float = 2.0


class Outer(StrictModel):
    inner: Inner = Inner()
    flag: Optional[Inner] = None  # a section that may be given as null
    free: dict[str, Any] = {}
    items: list[Inner] = []
    number: float = 0.0


def test_an_unknown_key_is_named_with_the_keys_allowed_there():
    with pytest.raises(ConfigError) as err:
        apply_overrides(load_scene("paper").model_dump(), {"spinner.rmp": 1.0}, Scene)
    assert err.value.key == "spinner.rmp"
    assert err.value.message == "unknown key; known keys here: " + ", ".join(sorted(Scene.model_fields["spinner"]
                                                                                     .annotation.model_fields))
    with pytest.raises(ConfigError, match=r"^nmber: unknown key; known keys here: flag, free, inner, items, number$"):
        apply_overrides({}, {"nmber": 1.0}, Outer)


def test_the_schema_not_the_tree_says_what_exists():
    tree = {"number": 3.0, "flag": None}
    assert apply_overrides(tree, {"inner.a": 5.0}, Outer) == {"number": 3.0, "flag": None, "inner": {"a": 5.0}}
    assert tree == {"number": 3.0, "flag": None}  # the input is not changed
    # an optional section given as null opens on a dotted key (`--set twin.spacing_m=0.8`)
    assert apply_overrides(tree, {"flag.a": 4.0}, Outer)["flag"] == {"a": 4.0}
    with pytest.raises(ConfigError, match=r"^number: is not a section; set it as a whole$"):
        apply_overrides(tree, {"number.x": 1.0}, Outer)
    assert apply_overrides(tree, {"free.spinner.rpm": 600.0}, Outer)["free"] == {"spinner.rpm": 600.0}


def test_list_items_follow_the_item_schema():
    assert apply_overrides({"items": [{}]}, {"items.0.b": 4.0}, Outer) == {"items": [{"b": 4.0}]}
    assert apply_overrides({"items": [{}]}, {"items[0].b": 4.0}, Outer) == {"items": [{"b": 4.0}]}  # the docs' form
    with pytest.raises(ConfigError, match=r"^items\.0\.c: unknown key; known keys here: a, b$"):
        apply_overrides({"items": [{}]}, {"items.0.c": 4.0}, Outer)
    with pytest.raises(ConfigError, match=r"^items\.0: the list is empty here"):
        apply_overrides({"items": []}, {"items.0.b": 4.0}, Outer)
    tree = load_scene_dict("paper-deflectors")
    scene = load_scene("paper-deflectors", {"deflectors.0.length_m": 0.15})
    assert scene.deflectors[0].length_m == 0.15 and tree["deflectors"][0]["length_m"] == 0.2
    with pytest.raises(ConfigError, match=r"^deflectors\.9: list index must be 0\.\.1$"):
        load_scene("paper-deflectors", {"deflectors.9.length_m": 0.15})


def test_a_dotted_key_opens_an_optional_section_the_scene_sets_to_null():
    from spreadgym.config.scene import load_scene

    twin = load_scene("paper", {"twin.spacing_m": 0.8})
    assert twin.twin is not None and twin.twin.spacing_m == 0.8 and load_scene("paper").twin is None
