"""Compressed image bytes -> pixels: the one decoder of the images the camera_features nodes, the bag tools,
the suite and the benchmarks read.

JPEG goes through simplejpeg (libjpeg-turbo 3 with its SIMD code, in the wheel), which decodes into a
NumPy array: a 1080p frame of the default bag takes 4.4 ms of CPU. cv2.imdecode (OpenCV 5.0's wheel) takes
5.0 ms when its output lands in memory the process already has; where malloc hands it fresh pages
(as in some of the graph's nodes, depending on their heap) each decode also takes about 2000 page faults,
and 10 ms. The pixels are the same to the bit (all 150 images of the default bag, and OpenCV's own encodes
at quality 50–100 with 4:2:0, 4:2:2 and 4:4:4 chroma; tests/test_decoding.py).
Anything else (PNG: masks, ground-truth labels) goes through cv2.imdecode.
"""
import cv2
import numpy as np
import simplejpeg

JPEG_START = b'\xff\xd8'   # the start-of-image marker every JPEG begins with (ITU-T T.81 B.1.1.3)


def decode_image(data, mono=False):
    """The pixels of encoded image bytes (JPEG or any format OpenCV reads): RGB uint8 (H, W, 3), or with
    `mono` grey uint8 (H, W); None when the bytes do not decode."""
    data = bytes(data)
    if not data:
        return None
    if data[:2] == JPEG_START:
        try:
            pixels = simplejpeg.decode_jpeg(data, 'GRAY' if mono else 'RGB')
        except ValueError:   # simplejpeg's error for data libjpeg-turbo cannot decode
            return None
        return pixels[..., 0] if mono else pixels
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE if mono else cv2.IMREAD_COLOR_RGB)
