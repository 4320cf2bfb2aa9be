"""lapwrench.robot_kinds: the shipped arms' names, and why the asked-for ones are absent."""

from __future__ import annotations

import pytest

from lapwrench.robot.arms import ARM_SPECS
from lapwrench.robot_kinds import NOT_SHIPPED, ROBOT_KINDS, unknown_kind_message


def test_the_names_are_the_registered_arms_in_order() -> None:
    assert tuple(ARM_SPECS) == ROBOT_KINDS
    assert not set(NOT_SHIPPED) & set(ROBOT_KINDS)


@pytest.mark.parametrize(("kind", "words"), [("ur5e", "use ur5"), ("gen3", "use xarm7"), ("kuka", "choose one of")])
def test_an_absent_arm_is_explained_in_one_line(kind: str, words: str) -> None:
    msg = unknown_kind_message(kind)
    assert kind in msg and words in msg and "\n" not in msg


def test_a_huge_name_is_cut() -> None:
    assert len(unknown_kind_message("x" * 10_000)) < 200
