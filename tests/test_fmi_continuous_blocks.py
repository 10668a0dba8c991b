"""bdsim-style block kinds: a block with continuous state says so by its base class.

:class:`~robofmu.components.blocks.ContinuousBlock` makes a block implement the hooks a
monolithic reference integrates it with (``continuous_state``, ``set_continuous_state``,
``derivative``: abstract there). A subclass without one of them cannot be instantiated, and a
concrete one (that would register) is refused when it is defined. Every other block has an
empty continuous state.
"""
from __future__ import annotations

import numpy as np
import pytest

from robofmu.components.blocks import Block, ContinuousBlock, block_class, make_block, registered
from robofmu.components.robots import load_model

from fmu_util import robot_blocks


@pytest.mark.parametrize("robot, kind", robot_blocks())
def test_a_block_has_continuous_state_exactly_when_it_is_a_continuous_block(robot, kind):
    block = make_block(robot, kind)
    block.configure()
    x = block.continuous_state()
    assert isinstance(block, ContinuousBlock) == (x.size > 0), (type(block).__name__, x.size)
    assert block.derivative(0.0).shape == x.shape


def test_plant_and_controller_are_the_continuous_blocks():
    continuous = {kind for kind, variant in registered() if issubclass(block_class(kind, variant), ContinuousBlock)}
    assert continuous == {"plant", "controller"}


def _without_derivative(**attributes):
    def declare(self):
        self.real("x0", "parameter", "1", "Initial state", 0.0)

    namespace = {"declare": declare, "continuous_state": lambda self: np.zeros(1),
                 "set_continuous_state": lambda self, x: None, **attributes}
    return type("NoDerivative", (ContinuousBlock,), namespace)


def test_a_continuous_block_without_its_derivative_cannot_be_instantiated():
    cls = _without_derivative(abstract=True)          # not registered: the class alone
    assert cls.__abstractmethods__ == frozenset({"derivative"})
    with pytest.raises(TypeError, match="abstract.*derivative"):
        cls(load_model("chess"))


def test_a_concrete_continuous_block_without_its_derivative_is_refused_when_defined():
    before = registered()
    with pytest.raises(TypeError, match=r"NoDerivative: a block with continuous state must implement derivative\(\)"):
        _without_derivative(kind="no-derivative", summary="a test block without a derivative")
    assert registered() == before


def test_a_block_without_continuous_state_needs_none_of_the_hooks():
    class Stateless(Block):
        abstract = True

        def declare(self):
            self.real("u", "input", "1", "An input")

    block = Stateless(load_model("chess"))
    assert block.continuous_state().size == 0 and block.derivative(0.0).size == 0


def test_the_registered_kinds_are_exactly_the_kinds_a_description_may_list():
    from robofmu.components.robots.description import KNOWN_BLOCKS

    assert {kind for kind, _ in registered()} == set(KNOWN_BLOCKS)


def test_a_block_of_a_kind_no_description_knows_is_refused_when_defined():
    before = registered()
    with pytest.raises(TypeError, match=r"Odd: block kind 'odd' is not one a robot description may list \(trajectory, "):
        type("Odd", (Block,), {"kind": "odd", "summary": "a kind of its own", "feedthrough": False})
    assert registered() == before
