"""Frames at the camera's full resolution reduced to the engine's pixels on the device.

`reduce_frames` is `dpom_warp.resolution.reduce_depth` (its NumPy reference) as a kernel: on a GPU
the engine takes full-resolution frames and reduces them there, where the host's sorts took most
of a batched frame (2 to 4 ms of 3.4 to 4.5 on an H200). It selects readings and computes none,
so its frames equal the reference's bit for bit.
"""

import warp as wp

NEAREST, MIN, MEDIAN = 0, 1, 2
HOW = {"nearest": NEAREST, "min": MIN, "median": MEDIAN}


@wp.func
def valid_reading(z: wp.float32, z_max: wp.float32):
    return z > wp.float32(0.0) and z <= z_max  # (NaN: neither)


@wp.kernel
def reduce_frames(full: wp.array3d(dtype=wp.float32), stride: int, how: int, z_max: wp.float32, need: int,
                  out: wp.array3d(dtype=wp.float32)):
    """out[f, y, x] from the stride x stride block of full[f] at (y * stride, x * stride):
    NEAREST, the block's centre reading as it is; MIN and MEDIAN, of the block's valid readings
    (0 < z <= z_max), the smallest and the lower median (the ((n - 1) // 2)-th smallest of n),
    or 0 where fewer than `need` are valid. The median is found by rank (a valid reading's
    count of smaller ones, equal ones earlier in the block counted smaller), which picks the
    value a sort picks."""
    f, y, x = wp.tid()
    s = stride
    y0 = y * s
    x0 = x * s
    if how == NEAREST:
        out[f, y, x] = full[f, y0 + s // 2, x0 + s // 2]
        return
    n = int(0)
    low = wp.float32(wp.inf)
    for i in range(s * s):
        z = full[f, y0 + i // s, x0 + i % s]
        if valid_reading(z, z_max):
            n += 1
            low = wp.min(low, z)
    got = wp.float32(0.0)
    if n >= need:
        if how == MIN:
            got = low
        else:
            pick = (n - 1) // 2
            for i in range(s * s):
                a = full[f, y0 + i // s, x0 + i % s]
                if valid_reading(a, z_max):
                    rank = int(0)
                    for j in range(s * s):
                        b = full[f, y0 + j // s, x0 + j % s]
                        if valid_reading(b, z_max) and (b < a or (b == a and j < i)):
                            rank += 1
                    if rank == pick:
                        got = a
                        break
    out[f, y, x] = got
