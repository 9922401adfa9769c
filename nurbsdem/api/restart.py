"""Restarting a scene built in Python from its checkpoint: the checkpoint stores the deck
text of the scene and of the steps run (:attr:`~nurbsdem.simulation.Simulation.deck_text`);
the scene built again must give the same scene lines, and each step called again the same
step line as the step of that number in the checkpoint."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..model import Step


def split_deck(text: str) -> tuple[list[str], list[str]]:
    """(scene lines, step lines) of a generated deck (Output block left out)."""
    lines = text.splitlines()
    try:
        a = lines.index("Steps")
    except ValueError:
        return lines, []
    b = lines.index("Output", a) if "Output" in lines[a:] else len(lines)
    return lines[:a], lines[a + 1:b]


def checkpoint_of_scene(path: Path, deck_text: str) -> tuple[dict, list[str]]:
    """(the checkpoint's state, its step lines): the checkpoint at ``path`` read and checked
    to have been written for the scene of ``deck_text`` (the Output block aside)."""
    from ..io.checkpoint import load_checkpoint
    st = load_checkpoint(path)
    deck = st.get("deck")
    if not isinstance(deck, str) or "time" not in st:
        raise InputError("not a nurbsdem checkpoint of a run (no deck or time in it)",
                         path=str(path))
    old_scene, old_steps = split_deck(deck)
    new_scene, _ = split_deck(deck_text)
    if old_scene != new_scene:
        here = [x.strip() for x in new_scene if x not in old_scene]
        there = [x.strip() for x in old_scene if x not in new_scene]
        what = (f"here, not in the checkpoint: {here[0]!r}" if here
                else f"in the checkpoint, not here: {there[0]!r}" if there
                else "the order of its entries")
        raise InputError(f"the checkpoint was written for a different scene ({what}); "
                         f"build the scene that wrote it", path=str(path))
    return st, old_steps


def check_restart_step(step: Step, k: int, done: list[str], deck_text: str,
                       path: Path | None) -> None:
    """Step ``k`` (from 0) of ``deck_text`` must be the step of that number the checkpoint at
    ``path`` has run or started (``done``: its step lines), if it has."""
    lines = split_deck(deck_text)[1]
    if done and k < len(done) and lines[k] != done[k]:
        raise InputError(f"Step {step.id} is not the step the checkpoint ran as step "
                         f"{step.id} ({done[k].strip()!r}, here "
                         f"{lines[k].strip()!r}): run the same steps to continue it",
                         path=str(path))
