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


@pytest.mark.parametrize("argv, message", [
    (["--interleaved"], "--interleaved needs --silo or --pour-bed"),
    (["--pour-bed", "--pour-seeds", "2", "--interleaved"], "without --pour-seeds"),
    (["--silo", "--tuning", "relaxation=1.0"], "--tuning needs --interleaved"),
    (["--pour-bed", "--step-fraction", "0.2"], "--step-fraction needs --pour-bed --interleaved"),
    (["--pour-bed", "--interleaved", "--step-fraction", "1.5"],
     "step_fraction must be a number in (0, 1], got 1.5"),
    (["--pour-bed", "--interleaved", "--tuning", "relax=1.0"], "unknown tuning field 'relax'"),
    (["--window", "0.1"], "--window and --repeats need --silo or --interleaved"),
    (["--pour-bed", "--interleaved", "--window", "0"], "--window takes seconds > 0"),
])
def test_bad_option_combinations_are_refused(argv, message, capsys):
    """The interleaved mode's options are checked before any worktree is made."""
    with pytest.raises(SystemExit):
        ab_revisions.main(["HEAD~1", "HEAD", *argv])
    assert message in capsys.readouterr().err


def test_kernel_compiles_table_compares_the_revisions_kernel_by_kernel():
    import kernel_compiles    # (tools/kernel_compiles.py)
    a = kernel_compiles.medians([dict(wall=4.0, kernels=dict(solve=2.0, drift=0.5)),
                                 dict(wall=6.0, kernels=dict(solve=3.0, drift=0.5))])
    b = dict(wall=2.5, kernels=dict(solve=1.5, load=0.25))
    rows = kernel_compiles.table(("old", "new"), "pour", "fast", dict(old=a, new=b), top=3)
    assert rows[0] == "| pour | fast | first step (build + advance) | 5.00 | 2.50 | 0.50 |"
    assert rows[1] == "| | | all kernels' compiles | 3.00 | 1.75 | 0.58 |"
    assert rows[2:] == ["| | | solve | 2.50 | 1.50 | 0.60 |", "| | | drift | 0.50 | 0.00 | 0.00 |",
                        "| | | load | 0.00 | 0.25 | new |"]
