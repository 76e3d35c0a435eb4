"""The alive (message) counter of ValveCommand frames, checked as J1939 and CiA 447 receivers do.

A sender adds one (mod 256) to the counter with every frame of a joint. A repeated counter means
the sender's application is stuck while its CAN controller keeps repeating the last frame; a jump
means frames were lost. Both are counted. Up to ``limit`` errors in a row are tolerated (a single
lost frame, a sender that restarted its count); past the limit frames are treated as lost: they do
not refresh the command, so the command watchdog puts the valve in its safe (neutral) state. The
first frame whose counter steps by one from the previous frame recovers. ``limit`` 0 switches the
check off.
"""

from __future__ import annotations

OK, STUCK, JUMP = "ok", "stuck", "jump"


class AliveCounters:
    def __init__(self, n_joints: int, limit: int = 3):
        self.limit = int(limit)
        self.last = [-1] * n_joints      # previous frame's counter, -1 before the first one
        self.errors_in_a_row = [0] * n_joints
        self.lost = [False] * n_joints   # past the limit: frames are treated as lost

    def check(self, a: int, counter: int) -> tuple[str, bool]:
        """(what the counter did, whether to apply the frame)."""
        prev, self.last[a] = self.last[a], counter
        if self.limit <= 0 or prev < 0 or counter == (prev + 1) & 0xFF:
            self.errors_in_a_row[a] = 0
            self.lost[a] = False
            return OK, True
        self.errors_in_a_row[a] += 1
        apply = self.errors_in_a_row[a] <= self.limit
        self.lost[a] = not apply
        return (STUCK if counter == prev else JUMP), apply
