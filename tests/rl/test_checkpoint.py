"""Checkpoint helpers: the git state recorded with a run."""

from robot_hoi.rl.checkpoint import git_state


def test_git_state_is_empty_without_a_checkout():
    """Under an installed wheel there is no repository (REPO_ROOT None): no git call into whatever folder holds
    site-packages."""
    assert git_state(None) == {"commit": "", "diff": ""}

