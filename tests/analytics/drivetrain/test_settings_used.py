"""Every setting of a mill file is used or refused.

Refused: every model of the :class:`MillConfig` tree forbids unknown fields. Used: every field
name is read as an attribute (``config.<…>.name``) somewhere in the non-test source, outside
the validators (a validator checks a value, it does not use it). A field consumed only
generically (by ``getattr`` with a computed name, or by a model dump) goes in the allow-list
below, with the reason.
"""

from __future__ import annotations

import ast
import typing
from pathlib import Path

import pytest
from pydantic import BaseModel

from millwatch.analytics.drivetrain.mill_config import MillConfig

ROOT = Path(__file__).resolve().parents[3]
SOURCE = ("analytics", "ingest", "alarms", "service")
_VALIDATORS = {"field_validator", "model_validator"}

#: Fields read only generically: (model, field) → how they are consumed.
ALLOWED: dict[tuple[str, str], str] = {}


def model_tree(model: type[BaseModel]) -> dict[type[BaseModel], list[str]]:
    """Every pydantic model reachable from ``model``'s field annotations, with its fields."""
    out: dict[type[BaseModel], list[str]] = {}
    todo = [model]
    while todo:  # bounded: each model class is visited once, and the tree is finite
        m = todo.pop()
        if m in out:
            continue
        out[m] = list(m.model_fields)
        types = [f.annotation for f in m.model_fields.values()]
        while types:  # bounded: annotations are finite trees
            t = types.pop()
            if isinstance(t, type) and issubclass(t, BaseModel):
                todo.append(t)
            types += typing.get_args(t)
    return out


def _validator_nodes(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and any(
            isinstance(d, ast.Call) and getattr(d.func, "id", None) in _VALIDATORS
            for d in node.decorator_list
        ):
            skip |= {id(n) for n in ast.walk(node)}
    return skip


def attributes_read() -> set[str]:
    """Names read as attributes (``x.name`` in a load context) in the source packages, outside
    pydantic validators."""
    names: set[str] = set()
    for package in SOURCE:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            skip = _validator_nodes(tree)
            names |= {
                n.attr
                for n in ast.walk(tree)
                if isinstance(n, ast.Attribute)
                and isinstance(n.ctx, ast.Load)
                and id(n) not in skip
            }
    return names


TREE = model_tree(MillConfig)


def test_the_tree_holds_every_section():
    names = {m.__name__ for m in TREE}
    assert {"MillConfig", "DriveConfig", "ShaftConfig", "MaterialConfig", "ChannelConfig",
            "AlarmThresholds", "LifeConfig", "TorsionalParams"} <= names  # fmt: skip


@pytest.mark.parametrize("model", list(TREE), ids=lambda m: m.__name__)
def test_unknown_fields_are_refused(model: type[BaseModel]) -> None:
    assert model.model_config.get("extra") == "forbid"


@pytest.mark.parametrize("model", list(TREE), ids=lambda m: m.__name__)
def test_every_field_is_read_somewhere(model: type[BaseModel]) -> None:
    read = attributes_read()
    unread = [f for f in TREE[model] if f not in read and (model.__name__, f) not in ALLOWED]
    assert unread == [], f"{model.__name__} fields read nowhere: {unread}"


def test_the_scan_finds_a_field_nobody_reads():
    """The scan can fail: a name no source reads is reported."""
    assert "kt_torsion" in attributes_read()
    assert "no_such_setting_anywhere" not in attributes_read()
