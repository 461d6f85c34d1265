"""Stable ids for the nodes of a compiled tree: what the console, the recording and the report call a node.

A node's id is its path from the root: the root is ``"0"``, its second
child ``"0.1"``, that child's first child ``"0.1.0"``. Ids depend only on the
mission's structure, so they are the same for every run of a mission and
tell apart steps that share a name (two ``drive: 1 m`` in a loop).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import py_trees


@dataclass(frozen=True)
class TreeNode:
    """One node of the compiled tree: its stable ``id``, ``name``, ``kind`` and its parent's id (None: the root)."""

    id: str
    name: str
    kind: str
    parent: Optional[str]
    node: py_trees.behaviour.Behaviour

    def as_dict(self) -> dict:
        """``{id, name, kind, parent}`` (JSON-ready; the node itself is left out)."""
        return {"id": self.id, "name": self.name, "kind": self.kind, "parent": self.parent}


def kind_of(node: py_trees.behaviour.Behaviour) -> str:
    """What sort of node: ``sequence``, ``selector``, ``parallel``, ``composite``, ``decorator``, ``condition`` or ``action``."""
    from beastbt.behaviours.conditions import CheckCondition
    if isinstance(node, py_trees.composites.Sequence):
        return "sequence"
    if isinstance(node, py_trees.composites.Selector):
        return "selector"
    if isinstance(node, py_trees.composites.Parallel):
        return "parallel"
    if isinstance(node, py_trees.composites.Composite):
        return "composite"
    if isinstance(node, py_trees.decorators.Decorator):
        return "decorator"
    if isinstance(node, CheckCondition):
        return "condition"
    return "action"


def tree_layout(root: py_trees.behaviour.Behaviour) -> list[TreeNode]:
    """Every node of the tree under ``root``, parents before children (depth first, in child order)."""
    out: list[TreeNode] = []
    stack: list[tuple[py_trees.behaviour.Behaviour, str, Optional[str]]] = [(root, "0", None)]
    while stack:
        node, node_id, parent = stack.pop()
        out.append(TreeNode(node_id, node.name, kind_of(node), parent, node))
        for index in range(len(node.children) - 1, -1, -1):
            stack.append((node.children[index], f"{node_id}.{index}", node_id))
    return out


def node_ids(root: py_trees.behaviour.Behaviour) -> dict[int, str]:
    """``id(node)`` -> stable id, for every node under ``root``."""
    return {id(n.node): n.id for n in tree_layout(root)}


__all__ = ["TreeNode", "kind_of", "tree_layout", "node_ids"]
