"""tools/ab_revisions.py: its worktrees come and go with the block that uses them."""
import os
import subprocess
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tools"))
import ab_revisions  # noqa: E402  (tools/ab_revisions.py)


def listed_worktrees() -> str:
    return subprocess.run(["git", "-C", ab_revisions.ROOT, "worktree", "list"],
                          capture_output=True, text=True, check=True).stdout


def test_worktrees_hold_the_revision_and_go_when_the_block_ends():
    with ab_revisions.worktrees("HEAD") as trees:
        tree = trees["HEAD"]
        assert os.path.isfile(os.path.join(tree, "tools", "ab_revisions.py"))
        assert os.path.realpath(tree) in listed_worktrees()
    assert not os.path.exists(tree)
    assert os.path.realpath(tree) not in listed_worktrees()


def test_worktrees_go_when_the_block_fails():
    with pytest.raises(RuntimeError, match="stop"):
        with ab_revisions.worktrees("HEAD") as trees:
            tree = trees["HEAD"]
            raise RuntimeError("stop")
    assert not os.path.exists(tree)
    assert os.path.realpath(tree) not in listed_worktrees()
