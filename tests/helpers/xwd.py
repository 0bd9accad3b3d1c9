"""Screenshots of a virtual X screen: decode the frame buffer Xvfb writes with ``-fbdir``.

Used to capture the explorer window in tests and by the example's README screenshot script
(Xvfb keeps its screen as an XWD file in the ``-fbdir`` folder).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def xwd_to_rgb(path: str | Path) -> np.ndarray:
    """Decode an XWD file (ZPixmap, 32 bits per pixel, as Xvfb writes it) to an RGB uint8 array.

    Raises ValueError for another pixel depth.
    """
    data = Path(path).read_bytes()
    h = np.frombuffer(data[:100], dtype=">u4")
    header_size, width, height, byte_order, bpp, bpl = int(h[0]), int(h[4]), int(h[5]), int(h[7]), int(h[11]), int(h[12])
    masks, ncolors = (int(h[14]), int(h[15]), int(h[16])), int(h[19])
    if bpp != 32:
        raise ValueError(f"{path}: {bpp} bits per pixel; only 32 is supported")
    start = header_size + 12 * ncolors
    pixels = np.frombuffer(data[start:start + bpl * height], dtype="<u4" if byte_order == 0 else ">u4")
    pixels = pixels.reshape(height, bpl // 4)[:, :width]
    channels = [((pixels & m) >> (int(m) & -int(m)).bit_length() - 1).astype(np.uint8) for m in masks]
    return np.dstack(channels)
