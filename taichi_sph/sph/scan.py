"""Exclusive prefix sums inside Taichi kernels: one serial pass on the CPU, a blocked one on GPUs.

Counting sorts (the neighbour grid's cells, the multigrid's aggregates) and order-keeping compaction (the
PPE's row numbers, the list of moving particles) need start[c] = count[0] + ... + count[c - 1]. A loop
with a running sum is serial. On the CPU one thread runs it in microseconds for the counts at hand, and
a parallel form would cost more in thread-pool launches than it saves. On a GPU a serial loop runs on one
thread, a few tens of nanoseconds per element: tens of milliseconds for a million cells or particles,
every step. The blocked form splits the counts into blocks of `block` entries: each block summed by its
own thread (in order), the block totals scanned by one thread, and each entry then given its block's
offset in parallel. Both forms give the same integers, so nothing downstream depends on which ran.

    scan = PrefixSum(capacity)               # at most `capacity` counts; blocked on GPUs, serial on CPUs

    @ti.kernel
    def k(self):
        ...                                  # fill count[0:n]
        scan.exclusive(count, start, n)      # at the kernel's top level: its loops are the kernel's
"""

import math

import taichi as ti

from ..backend import on_cpu


@ti.data_oriented
class PrefixSum:
    """Exclusive prefix sums of up to `capacity` i32 counts. `blocked`: None picks the blocked form on GPUs
    and the serial one on CPUs (tests force either)."""

    def __init__(self, capacity: int, blocked: bool | None = None):
        self.capacity = max(int(capacity), 1)
        self.blocked = (not on_cpu()) if blocked is None else bool(blocked)
        # about sqrt(capacity) per block: the serial scan of the block totals and each block's own pass
        # are then about equally long
        self.block = max(64, 1 << math.ceil(math.log2(math.sqrt(self.capacity))))
        self.sums = ti.field(ti.i32, (self.capacity + self.block - 1) // self.block + 1 if self.blocked else 1)

    @ti.func
    def exclusive(self, count: ti.template(), start: ti.template(), n):
        """start[c] = count[0] + ... + count[c - 1] for c = 0 .. n (start[n] the total); `start` holds
        n + 1 entries. Call it at a kernel's top level."""
        self._scan(count, start, n, start, False)

    @ti.func
    def exclusive_with_copy(self, count: ti.template(), start: ti.template(), n, copy: ti.template()):
        """`exclusive`, and `copy` receives the same values (a counting sort's cursors)."""
        self._scan(count, start, n, copy, True)

    @ti.func
    def _scan(self, count: ti.template(), start: ti.template(), n, copy: ti.template(), with_copy: ti.template()):
        if ti.static(self.blocked):
            B = ti.static(self.block)
            nb = (n + B - 1) // B
            for b in range(nb):
                s = 0
                for c in range(b * B, ti.min((b + 1) * B, n)):
                    start[c] = s
                    s += count[c]
                self.sums[b] = s
            ti.loop_config(serialize=True)
            for _ in range(1):
                total = 0
                for b in range(nb):
                    t = self.sums[b]
                    self.sums[b] = total
                    total += t
                start[n] = total
                if ti.static(with_copy):
                    copy[n] = total
            for c in range(n):
                v = start[c] + self.sums[c // B]
                start[c] = v
                if ti.static(with_copy):
                    copy[c] = v
        else:
            ti.loop_config(serialize=True)
            for c in range(n + 1):
                s = 0
                if c > 0:
                    s = start[c - 1] + count[c - 1]
                start[c] = s
                if ti.static(with_copy):
                    copy[c] = s
