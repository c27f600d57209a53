"""What a run's picture costs, and its PNG encoding against Pillow's.

Draws the picture `dpom-warp run` writes for the first frame of a standard scene (rendered
once into .cache/bench/, as `python -m bench` does) and times, median of `--repeats` runs on
one core: the whole picture (render.frame_picture, drawing and encoding), the encoding alone
by render.encode_png (zlib level 1, rows unfiltered) and by Pillow (compress_level 1, its
per-row filter choice) of the same image, with the PNG sizes.

    python -m bench.pictures [--scene kinect_v2_far] [--repeats 10]
"""

from __future__ import annotations

import argparse
import io
import statistics
import time

import numpy as np

from bench.scenes import SCENES, load_scene


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000 * statistics.median(times)


def main():
    from PIL import Image

    from dpom_warp.api import Detector
    from dpom_warp.render import encode_png, frame_picture

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", choices=list(SCENES), default="kinect_v2_far")
    ap.add_argument("--repeats", type=int, default=10)
    a = ap.parse_args()
    cfg, depth, _ = load_scene(a.scene)  # renders the scene once
    path, sets = SCENES[a.scene]
    cache = f".cache/bench/{a.scene}"
    detector = Detector.from_config(path, list(sets) + [
        f"synthetic.cache={cache}", f"input.frames={cache}/frames/*.png", f"input.background={cache}/background/*.png",
        "synthetic.frames=2", "synthetic.background_frames=5", "device=cpu"])
    result = detector.detect(depth)
    geometry = detector.worker.geometry

    def picture():
        return frame_picture(depth, result.rho_star, cfg.grid, result.detections, geometry.centre[:2], None,
                             "frame", in_view=geometry.rect_area > 0)

    png = picture()
    image = Image.open(io.BytesIO(png))
    rgb = np.asarray(image.convert("RGB"))

    def pillow():
        out = io.BytesIO()
        image.save(out, format="PNG", compress_level=1)
        return out.getvalue()

    whole, ours, theirs = (median_ms(fn, a.repeats) for fn in (picture, lambda: encode_png(rgb), pillow))
    print(f"{a.scene}: a {rgb.shape[1]} x {rgb.shape[0]} picture {whole:.1f} ms (drawing and encoding); "
          f"encoding alone: render.encode_png {ours:.1f} ms ({len(encode_png(rgb)) / 1024:.0f} KiB), "
          f"Pillow {theirs:.1f} ms ({len(pillow()) / 1024:.0f} KiB); median of {a.repeats}, one core")

if __name__ == "__main__":
    main()
