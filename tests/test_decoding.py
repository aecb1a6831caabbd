"""vision.decoding.decode_image, the one decoder of the images the nodes, the bag tools and the suite read,
gives OpenCV's pixels to the bit (it decodes JPEG with libjpeg-turbo through simplejpeg, in half the time)."""
import cv2
import numpy as np
import pytest

from mvpose_nodes.vision.decoding import decode_image

pytestmark = pytest.mark.pure

SAMPLING = {'4:2:0': cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, '4:2:2': cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422,
            '4:4:4': cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444}


@pytest.fixture(scope='module')
def picture():
    """A (270, 481, 3) BGR uint8 picture with edges, gradients and noise (odd width: partial JPEG blocks)."""
    rng = np.random.default_rng(5)
    rows, columns = np.mgrid[0:270, 0:481]
    image = np.stack([(rows + columns) % 256, (3 * rows) % 256, (columns * 7) % 256], axis=-1).astype(np.int16)
    image[60:200, 150:330] = (200, 40, 90)
    image += rng.integers(-20, 21, size=image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


@pytest.mark.parametrize('quality', [50, 90, 100])
@pytest.mark.parametrize('sampling', SAMPLING)
def test_a_jpeg_decodes_to_opencvs_pixels(picture, quality, sampling):
    ok, data = cv2.imencode('.jpg', picture, [cv2.IMWRITE_JPEG_QUALITY, quality,
                                              cv2.IMWRITE_JPEG_SAMPLING_FACTOR, SAMPLING[sampling]])
    rgb, grey = decode_image(data), decode_image(data, mono=True)
    assert rgb.shape == picture.shape and rgb.dtype == np.uint8
    assert np.array_equal(rgb, cv2.cvtColor(cv2.imdecode(data, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))
    assert grey.shape == picture.shape[:2] and np.array_equal(grey, cv2.imdecode(data, cv2.IMREAD_GRAYSCALE))


def test_a_png_decodes_to_its_pixels(picture):
    ok, colour = cv2.imencode('.png', picture)
    ok, mask = cv2.imencode('.png', picture[..., 0])
    assert np.array_equal(decode_image(colour.tobytes()), picture[..., ::-1])
    assert np.array_equal(decode_image(mask.tobytes(), mono=True), picture[..., 0])


def test_bytes_that_do_not_decode_give_none(picture):
    ok, data = cv2.imencode('.jpg', picture)
    for broken in (data.tobytes()[:len(data) // 2], b'\xff\xd8 not a jpeg', b'', b'not an image at all'):
        assert decode_image(broken) is None, broken[:12]
