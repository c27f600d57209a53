"""Launches of a frame's kernels recorded at their first launch and replayed with only the
arguments that changed (a launch from Python takes ~15 to 30 us on the CPU, and a frame makes
~200). The engine launches the kernels over its locations through its own Launcher and each
camera's through the camera's (engine.view): a kernel keeps the arguments of its last launch,
so a camera's never thrash another's."""

from __future__ import annotations

import ctypes
import time

import warp as wp


def _direct(cmd):
    """(entry point, argument block, field names, its address) of a recorded CPU launch that
    Warp invokes with a ctypes block of its arguments (warp's `invoke`, whose block type it
    caches per kernel at the first launch), for Launcher.__call__ to call the entry point with
    a block it keeps; None where the launch is not such (a GPU, tiles, another Warp)."""
    try:
        if not cmd.device.is_cpu or cmd.block_dim > 1 or cmd.adjoint:
            return None
        cached = cmd.kernel._invoke_cache.get((tuple(type(p) for p in cmd.params[1:]), False))
        if cached is None:
            return None
        block_type, fields = cached
        block = block_type()
        names = [f[0] for f in fields]
        for i, name in enumerate(names):
            setattr(block, name, cmd.params[1 + i])
        return cmd.hooks.forward, block, names, ctypes.byref(block)
    except (AttributeError, TypeError, ValueError):
        return None


class _Recorded:
    """A Launcher's record of one kernel: Warp's recorded command, the dim and inputs of
    its last launch, its direct call (_direct's tuple; None: Warp's Launch.launch) and, for a
    direct call, the bounds of the current dim and those of each dim seen (ctypes refs)."""

    __slots__ = ("cmd", "dim", "inputs", "direct", "bounds", "bounds_of")

    def __init__(self, cmd, dim: int, inputs: list, direct):
        self.cmd, self.dim, self.inputs, self.direct = cmd, dim, list(inputs), direct
        self.bounds = ctypes.byref(cmd.params[0])
        self.bounds_of = {dim: self.bounds}


class Launcher:
    """wp.launch of a frame's kernels on one device, each recorded at its first launch (one
    record a kernel) and replayed after. `direct`: on the CPU outside a capture, replays call
    the kernel's entry point with an argument block kept between launches (`_direct`); off
    under a graph capture, where every launch must be Warp's. On the CPU, where a launch
    returns when its kernel is done, `seconds` adds up the time its launches took (a rig's
    time camera by camera); elsewhere it stays 0 (a GPU's launches return at once)."""

    def __init__(self, device: str, direct: bool = True):
        self.device, self.direct = device, direct
        self.recorded: dict = {}
        self.timed = str(device).startswith("cpu")
        self.seconds = 0.0

    def reset(self, direct: bool | None = None) -> None:
        """Forget the recorded launches (new buffers, or a capture to come)."""
        if direct is not None:
            self.direct = direct
        self.recorded = {}

    def __call__(self, kernel, dim: int, inputs: list):
        """launch(), timed on the CPU (`seconds`)."""
        if not self.timed:
            return self.launch(kernel, dim, inputs)
        t = time.perf_counter()
        self.launch(kernel, dim, inputs)
        self.seconds += time.perf_counter() - t

    def launch(self, kernel, dim: int, inputs: list):
        """wp.launch of one of a frame's kernels, recorded at its first launch (one record a
        kernel) and replayed after with only the arguments that changed: a launch from Python
        takes ~15 to 30 us on the CPU, and a frame makes ~200. On the CPU outside a capture a
        replay calls the kernel's entry point with an argument block kept between launches (its
        changed fields rewritten, its bounds kept per dim) instead of Warp's Launch.launch,
        which builds the block anew each time (`_direct`)."""
        rec = self.recorded.get(kernel)
        if rec is None:
            cmd = wp.launch(kernel, dim=dim, inputs=inputs, device=self.device, record_cmd=True)
            cmd.launch()
            self.recorded[kernel] = _Recorded(cmd, dim, inputs, _direct(cmd) if self.direct else None)
            return
        cmd, last, direct = rec.cmd, rec.inputs, rec.direct
        for i, v in enumerate(inputs):
            if v is not last[i] and not (type(v) is type(last[i]) and type(v) in (int, float) and v == last[i]):
                last[i] = v
                if direct is None:
                    cmd.set_param_at_index(i, v)
                elif type(v) in (int, float):  # (the iteration, the damping: the block's field takes it)
                    setattr(direct[1], direct[2][i], v)
                else:
                    cmd.set_param_at_index(i, v)
                    setattr(direct[1], direct[2][i], cmd.params[1 + i])
        if dim != rec.dim:
            rec.dim = dim
            if direct is None:
                cmd.set_dim(dim)
            else:  # the bounds of a dim seen before are reused (a few dims recur each frame)
                bounds = rec.bounds_of.get(dim)
                if bounds is None:
                    if len(rec.bounds_of) > 64:
                        rec.bounds_of.clear()
                    cmd.set_dim(dim)
                    bounds = rec.bounds_of[dim] = ctypes.byref(cmd.params[0])
                rec.bounds = bounds
        if direct is None:
            cmd.launch()
        else:
            direct[0](rec.bounds, direct[3])
