"""A small renderer of a team's own: a diffusely lit image of a textured Lambertian plane.

Pixel (i, j) has albedo a(i, j) (a checkerboard of two greys) and sees the sky radiance
L(w) = 1 + cos(theta) over its hemisphere; its value is the reflected radiance
a / pi * integral of L cos(theta) dw = a (1 + 2/3), estimated with cosine-weighted directions
(mysampler.CosineHemisphere): each sample contributes a L(w).  The exact image is in
ref.exr (written by ``python myrenderer.py --exact --out ref.exr``).

    python myrenderer.py --spp 64 --seed 3 --out image.exr            # one render
    python myrenderer.py --spp 64 --seed 3 --out image.exr --off-by-one   # the biased twin

The twin divides the sum of spp samples by spp + 1: a classic off-by-one, 1.5 % dark at 64 spp.
Prints "render time: <seconds> s", which the suite reads as the render's own time.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from mysampler import CosineHemisphere

WIDTH = HEIGHT = 24


def albedo() -> np.ndarray:
    """(HEIGHT, WIDTH) albedos: a checkerboard of 0.25 and 0.75 in 4 x 4 pixel squares."""
    i, j = np.indices((HEIGHT, WIDTH))
    return np.where((i // 4 + j // 4) % 2 == 0, 0.25, 0.75)


def exact() -> np.ndarray:
    return np.repeat((albedo() * 5 / 3)[:, :, None], 3, axis=2)


def render(spp: int, seed: int, off_by_one: bool = False) -> np.ndarray:
    """The image (HEIGHT, WIDTH, 3) from spp cosine-weighted samples per pixel."""
    rng = np.random.default_rng(seed)
    sampler = CosineHemisphere()
    total = np.zeros((HEIGHT, WIDTH))
    for _ in range(spp):
        w = sampler.sample(rng.random((HEIGHT * WIDTH, 2)))
        total += (1 + w[:, 2]).reshape(HEIGHT, WIDTH)     # L(w) a / pi cos / pdf = a L(w)
    mean = total / (spp + 1 if off_by_one else spp)
    return np.repeat((albedo() * mean)[:, :, None], 3, axis=2)


def write_exr(path: str, image: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(path)
    out.open(path, oiio.ImageSpec(image.shape[1], image.shape[0], image.shape[2], "float"))
    out.write_image(np.ascontiguousarray(image, dtype=np.float32))
    out.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    parser.add_argument("--off-by-one", action="store_true")
    parser.add_argument("--exact", action="store_true", help="write the exact image instead")
    args = parser.parse_args()
    start = time.perf_counter()
    image = exact() if args.exact else render(args.spp, args.seed, args.off_by_one)
    seconds = time.perf_counter() - start
    write_exr(args.out, image)
    print(f"render time: {seconds:.6f} s")


if __name__ == "__main__":
    main()
