#!/usr/bin/env python3
"""Submit a frame range, watch it converge, fetch it and denoise every frame.

    python examples/submit_and_denoise.py SCENE [--frames 1-24] [--coordinator HOST:PORT] [--spp N] [--res WxH]
        [-o DIR]

The token comes from $RAYFARM_TOKEN_FILE or $RAYFARM_TOKEN, TLS from $RAYFARM_TLS_CA, as for the
CLI. Denoising needs pyoidn (pip install pyoidn); the frames are rendered with the albedo and
normal AOVs it is fed.
"""

import argparse
import os
import sys

import rayfarm


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("--frames", default=None, help="frame range, e.g. 1-24 (default: one frame)")
    p.add_argument("--coordinator", default=None, help="default: $RAYFARM_COORDINATOR")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--res", default=None, help="WxH (default: the scene's)")
    p.add_argument("-o", "--output", default="out")
    a = p.parse_args()

    with rayfarm.Farm(a.coordinator) as farm:
        try:
            resolution = tuple(int(v) for v in a.res.split("x")) if a.res else None
            job = farm.submit(a.scene, frames=a.frames, spp=a.spp, resolution=resolution,
                              aovs=["albedo", "normal"])
        except rayfarm.SceneError as e:
            print(f"cannot submit: {e}", file=sys.stderr)
            return 2
        print(f"submitted {job.id}")
        for status in job.watch():
            eta = status.eta_seconds
            print(f"\r{job.id} {status.state} {status.progress:6.1%} "
                  f"ETA {'?' if eta is None else f'{eta:.0f} s'}   ", end="", flush=True)
        print()
        try:
            job.wait()
        except rayfarm.JobFailed as e:
            print(e, file=sys.stderr)
            return 1
        os.makedirs(a.output, exist_ok=True)
        for frame in job.fetch(os.path.join(a.output, "frame.####.exr")):
            denoised = frame.exr.replace(".exr", ".denoised.exr")
            rayfarm.denoise(frame, denoised)
            print(f"frame {frame.frame}: {frame.spp:.0f} spp, relMSE {frame.rel_mse} -> "
                  f"{frame.exr}, {denoised}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
