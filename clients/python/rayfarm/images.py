"""A fetched EXR as numpy arrays, and denoising with Intel Open Image Denoise (pyoidn) fed the
albedo and normal AOVs. The EXR is read with OpenImageIO's Python module, the library the engine
writes it with (Debian: python3-openimageio); the channel layout is docs/outputs.md's."""

from __future__ import annotations

import dataclasses
import os
from typing import Any

# Channel groups of a rayfarm EXR (docs/outputs.md), by layer name.
LAYERS = {
    "rgb": ("R", "G", "B"),
    "variance": ("variance.R", "variance.G", "variance.B"),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
    "normal": ("N.X", "N.Y", "N.Z"),
    "depth": ("Z",),
    "coverage": ("coverage",),
}


def _oiio():
    try:
        import numpy  # noqa: F401
        import OpenImageIO
    except ImportError as e:
        raise ImportError(f"reading EXR files needs numpy and OpenImageIO's Python module "
                          f"(Debian: sudo apt-get install python3-numpy python3-openimageio): "
                          f"{e}") from None
    return OpenImageIO


@dataclasses.dataclass
class Image:
    """An EXR's pixels: `layers` maps each layer present (LAYERS) to a float32 array of shape
    (height, width, channels) (or (height, width) for depth and coverage); `attributes` holds
    the header's metadata (the rayfarm:* provenance among it)."""

    path: str
    width: int
    height: int
    channels: tuple[str, ...]
    pixels: Any  # (height, width, len(channels)) float32
    attributes: dict[str, Any]

    @property
    def layers(self) -> dict[str, Any]:
        out = {}
        for name, group in LAYERS.items():
            if all(c in self.channels for c in group):
                index = [self.channels.index(c) for c in group]
                a = self.pixels[:, :, index]
                out[name] = a[:, :, 0] if len(group) == 1 else a
        return out

    @property
    def rgb(self):
        return self.layers["rgb"]


def read_exr(path: str) -> Image:
    oiio = _oiio()
    import numpy as np
    inp = oiio.ImageInput.open(path)
    if inp is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        if pixels is None:
            raise OSError(f"{path}: {inp.geterror()}")
        pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width,
                                                              spec.nchannels)
        attributes = {a.name: a.value for a in spec.extra_attribs}
        return Image(path, spec.width, spec.height, tuple(spec.channelnames), pixels, attributes)
    finally:
        inp.close()


def write_exr(path: str, rgb, attributes: dict[str, Any] | None = None) -> str:
    """Writes an RGB float image as a zip-compressed EXR, through a temporary file and a rename
    (a reader never sees half a file), with the given header attributes."""
    oiio = _oiio()
    import numpy as np
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    height, width = rgb.shape[:2]
    spec = oiio.ImageSpec(width, height, 3, "float")
    spec.channelnames = ("R", "G", "B")
    spec.attribute("compression", "zip")
    for name, value in (attributes or {}).items():
        if isinstance(value, (int, float, str)):
            spec.attribute(name, value)
    tmp = os.path.join(os.path.dirname(os.path.abspath(path)),
                       f".{os.path.basename(path)}.tmp-{os.getpid()}.exr")
    out = oiio.ImageOutput.create(tmp)
    if out is None or not out.open(tmp, spec) or not out.write_image(rgb):
        raise OSError(f"{path}: {oiio.geterror() or (out.geterror() if out else '')}")
    out.close()
    os.replace(tmp, path)
    return path


def denoise(image, output: str | None = None, quality: str | None = None):
    """Denoises a fetched frame (an Image, a Frame or an EXR path) with Open Image Denoise's RT
    filter for HDR images, fed the albedo and normal AOVs when the render asked for them
    (submit(..., aovs=["albedo", "normal"])): auxiliary images keep edges and texture that the
    colour alone loses. Returns the denoised RGB array; writes it as an EXR when `output` is
    given (the source's rayfarm:* attributes, plus rayfarm:denoised)."""
    try:
        import pyoidn
    except ImportError as e:
        raise ImportError(f"denoising needs pyoidn (pip install pyoidn): {e}") from None
    if isinstance(image, str):
        image = read_exr(image)
    elif not isinstance(image, Image):
        image = image.image  # a Frame
    layers = image.layers
    aux = {}
    if "albedo" in layers:
        aux["albedo"] = layers["albedo"]
        if "normal" in layers:  # OIDN takes a normal only beside an albedo
            aux["normal"] = layers["normal"]
    kwargs = {"hdr": True}
    if quality:
        kwargs["quality"] = quality
    result = pyoidn.denoise(layers["rgb"], **aux, **kwargs)
    if output:
        attributes = {k: v for k, v in image.attributes.items() if k.startswith("rayfarm:")}
        attributes["rayfarm:denoised"] = "oidn " + ("+".join(["rgb"] + sorted(aux)))
        write_exr(output, result, attributes)
    return result
