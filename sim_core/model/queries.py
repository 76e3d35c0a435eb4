"""Questions about a kinematic tree that several packages ask (pure functions of its arrays)."""

from __future__ import annotations


def subtree(tree, dof: str) -> list[int]:
    """Indices of the body moved by joint ``dof`` and of every body beyond it."""
    i = tree.index(dof)
    inside = [i]
    for c in range(tree.n):
        if int(tree.parent[c]) in inside:
            inside.append(c)
    return inside


def subtree_mass(tree, dof: str) -> float:
    """Mass (kg) that joint ``dof`` carries: its body and every body beyond it."""
    return float(sum(tree.mass[c] for c in subtree(tree, dof)))
