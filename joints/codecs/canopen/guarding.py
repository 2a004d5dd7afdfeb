"""CANopen node guarding (A2): the node's toggling reply and the master's check.

Rule: pure state machines; the link or the twin owns the clock.
"""

from __future__ import annotations

import can

from joints.codecs.canopen.cob import check_node
from joints.codecs.canopen.messages import GuardRequest, Heartbeat, encode
from joints.codecs.canopen.nmt import NmtState
from joints.errors import UnexpectedReply

__all__ = ["GuardingMaster", "GuardingSlave"]

# --- node guarding --------------------------------------------------------------------------------


class GuardingSlave:
    """Node side of node guarding: the reply to each :class:`GuardRequest`, toggling bit 7."""

    def __init__(self, node: int) -> None:
        check_node(node)
        self.node = node
        self._toggle = False

    def reset(self) -> None:
        """NMT reset communication: the next reply has toggle 0 again."""
        self._toggle = False

    def reply(self, state: NmtState) -> can.Message:
        frame = encode(Heartbeat(self.node, state, self._toggle))
        self._toggle = not self._toggle
        return frame


class GuardingMaster:
    """Master side of node guarding: the request frame, and the check of each reply's toggle bit."""

    def __init__(self, node: int) -> None:
        check_node(node)
        self.node = node
        self._expect = False

    def reset(self) -> None:
        """After NMT reset communication of the node (its toggle restarts at 0)."""
        self._expect = False

    def request(self) -> can.Message:
        return encode(GuardRequest(self.node))

    def check(self, reply: Heartbeat) -> NmtState:
        """The node's state from a guarding reply; :class:`~joints.errors.UnexpectedReply` if the toggle
        bit did not alternate (CiA 301: the master then treats the node as lost)."""
        if reply.node != self.node:
            raise UnexpectedReply(f"guarding reply of node {reply.node}, expected node {self.node}")
        if reply.toggle != self._expect:
            raise UnexpectedReply(f"node {self.node}: guarding toggle bit {int(reply.toggle)}, "
                                  f"expected {int(self._expect)}")
        self._expect = not self._expect
        return reply.state
