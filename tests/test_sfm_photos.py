"""Photo checks of the sfm stage: EXIF focal, bad JPEGs, too few photos; photos never modified."""

from __future__ import annotations

import hashlib
import logging

import numpy as np
import pytest

from scenebot.sfm.photos import (
    Photo,
    PhotoError,
    check_photos,
    inspect_photo,
    photos_from_folder,
)
from scenebot.testing.sfm import write_jpeg_with_exif


def _img(seed=0, w=160, h=120):
    return np.random.default_rng(seed).integers(0, 255, (h, w, 3), dtype=np.uint8)


def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("focal", [100.0, 212.5, 480.0])
def test_exif_focal_is_recovered(tmp_path, focal):
    path = tmp_path / "a.jpg"
    write_jpeg_with_exif(path, _img(), focal)
    p = Photo(name="a.jpg", path=path)
    inspect_photo(p)
    assert (p.width, p.height) == (160, 120)
    assert p.focal_source == "exif_focal_plane"
    assert p.focal_px == pytest.approx(focal, rel=1e-4)


def test_missing_exif_focal_falls_back_with_a_log_message(tmp_path, caplog):
    for i in range(3):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), None if i == 1 else 150.0)
    _, photos = photos_from_folder(tmp_path)
    with caplog.at_level(logging.WARNING):
        check_photos(photos, fallback_focal_factor=1.2)
    assert photos[1].focal_source == "fallback"
    assert photos[1].focal_px == pytest.approx(1.2 * 160)
    assert photos[0].focal_px == pytest.approx(150.0, rel=1e-4)
    assert "p1.jpg" in caplog.text and "fallback_focal_factor" in caplog.text


def test_corrupt_and_truncated_jpegs_are_named_and_left_alone(tmp_path):
    for i in range(4):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    data = (tmp_path / "p1.jpg").read_bytes()
    (tmp_path / "p1.jpg").write_bytes(data[: len(data) // 2])  # truncated
    (tmp_path / "p3.jpg").write_bytes(b"\xff\xd8\xff\xe0 definitely not a jpeg" * 10)
    before = _digest(tmp_path)
    _, photos = photos_from_folder(tmp_path)
    with pytest.raises(PhotoError) as exc:
        check_photos(photos, 1.2)
    msg = str(exc.value)
    assert "p1.jpg" in msg and "p3.jpg" in msg
    assert "p0.jpg" not in msg and "p2.jpg" not in msg
    assert "2 unusable photo(s)" in msg
    assert _digest(tmp_path) == before


def test_fewer_than_three_photos(tmp_path):
    for i in range(2):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    _, photos = photos_from_folder(tmp_path)
    with pytest.raises(PhotoError, match=r"at least 3 photos, got 2 .*p0\.jpg.*p1\.jpg"):
        check_photos(photos, 1.2)
    with pytest.raises(PhotoError, match="does not exist"):
        photos_from_folder(tmp_path / "nope")


def test_changed_photo_resets_the_database(tmp_path):
    from scenebot.sfm.config import SfmConfig
    from scenebot.sfm.features import check_database_photos, extract, open_database

    folder = tmp_path / "photos"
    folder.mkdir()
    for i in range(3):
        write_jpeg_with_exif(folder / f"p{i}.jpg", _img(i), 150.0)
    root, photos = photos_from_folder(folder)
    check_photos(photos, 1.2)
    db = tmp_path / "db" / "database.db"
    assert extract(db, root, photos, SfmConfig())["new"] == 3
    assert not check_database_photos(db, photos)
    assert extract(db, root, photos, SfmConfig())["new"] == 0  # reused
    write_jpeg_with_exif(folder / "p1.jpg", _img(7), 150.0)  # a re-captured photo
    assert check_database_photos(db, photos)
    assert (tmp_path / "db" / "database.db.stale").exists()
    assert extract(db, root, photos, SfmConfig())["new"] == 3
    with open_database(db) as d:
        assert d.num_images() == 3


def _png_like(jpg, png):
    """``jpg`` re-saved as a PNG with the same pixels and EXIF (a PNG's eXIf chunk)."""
    from PIL import Image

    with Image.open(jpg) as im:
        im.save(png, "PNG", exif=im.getexif())


def test_photo_suffixes_in_any_case_are_photos_of_the_folder(tmp_path):
    """`0007.Jpg` is a photo: one definition of what a photo file is, for the workflow's
    sfm rule (its inputs) and for the reader; in natural order of names."""
    from scenebot.sfm.photofiles import photo_files

    names = ["0007.Jpg", "0010.jpeg", "0002.JPG", "0001.jpg", "0003.JPEG", "0008.PNG"]
    for i, n in enumerate(names):
        write_jpeg_with_exif(tmp_path / f"tmp{i}.jpg", _img(i), 150.0)
        (tmp_path / f"tmp{i}.jpg").rename(tmp_path / n)
    (tmp_path / "0008.PNG").unlink()
    write_jpeg_with_exif(tmp_path / "src.jpg", _img(8), 150.0)
    _png_like(tmp_path / "src.jpg", tmp_path / "0008.PNG")
    (tmp_path / "src.jpg").unlink()
    (tmp_path / "notes.txt").write_text("not a photo")
    (tmp_path / "._0001.jpg").write_bytes(b"\x00\x05\x16\x07 AppleDouble")  # macOS metadata
    (tmp_path / "sub.jpg").mkdir()  # a folder is not a photo
    expected = ["0001.jpg", "0002.JPG", "0003.JPEG", "0007.Jpg", "0008.PNG", "0010.jpeg"]
    assert [p.name for p in photo_files(tmp_path)] == expected
    _, photos = photos_from_folder(tmp_path)
    assert [p.name for p in photos] == expected
    check_photos(photos, 1.2)


def test_names_in_natural_order():
    from scenebot.sfm.photofiles import photo_order

    names = ["img10.jpg", "IMG2.jpg", "img1.jpg", "img2.jpg", "b.jpg", "A.jpg"]
    assert sorted(names, key=photo_order) == [
        "A.jpg", "b.jpg", "img1.jpg", "IMG2.jpg", "img2.jpg", "img10.jpg"
    ]  # fmt: skip


def test_a_png_is_read_as_a_photo_with_its_exif_focal(tmp_path):
    for i in range(3):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    _png_like(tmp_path / "p1.jpg", tmp_path / "p1.png")
    (tmp_path / "p1.jpg").unlink()
    before = _digest(tmp_path)
    _, photos = photos_from_folder(tmp_path)
    check_photos(photos, 1.2)
    png = next(p for p in photos if p.name == "p1.png")
    assert (png.width, png.height) == (160, 120)
    assert png.focal_px == pytest.approx(150.0, rel=1e-4)
    assert _digest(tmp_path) == before


def test_a_16_bit_png_is_refused_naming_the_file(tmp_path):
    from PIL import Image

    for i in range(3):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    Image.fromarray(_img(5)[..., 0].astype(np.uint16) * 257).save(tmp_path / "deep.png")
    _, photos = photos_from_folder(tmp_path)
    with pytest.raises(PhotoError, match=r"deep\.png.*16 bits"):
        check_photos(photos, 1.2)


def test_the_same_photo_twice_is_left_out_with_a_warning_naming_both(tmp_path, caplog):
    for i in range(4):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    (tmp_path / "p9 copy.jpg").write_bytes((tmp_path / "p1.jpg").read_bytes())
    (tmp_path / "x1.JPG").write_bytes((tmp_path / "p1.jpg").read_bytes())
    before = _digest(tmp_path)
    with caplog.at_level(logging.WARNING):
        _, photos = photos_from_folder(tmp_path)
    assert [p.name for p in photos] == ["p0.jpg", "p1.jpg", "p2.jpg", "p3.jpg"]
    assert "x1.JPG" in caplog.text and "p9 copy.jpg" in caplog.text
    assert "same bytes as p1.jpg" in caplog.text and "left out" in caplog.text
    assert _digest(tmp_path) == before


def test_an_empty_file_and_a_non_image_are_named(tmp_path):
    for i in range(3):
        write_jpeg_with_exif(tmp_path / f"p{i}.jpg", _img(i), 150.0)
    (tmp_path / "empty.jpg").write_bytes(b"")
    (tmp_path / "empty2.JPG").write_bytes(b"")  # two empty files are not "duplicates"
    (tmp_path / "text.png").write_text("hello")
    from PIL import Image

    Image.fromarray(_img(4)).save(tmp_path / "anim.jpg", "GIF")
    _, photos = photos_from_folder(tmp_path)
    with pytest.raises(PhotoError) as exc:
        check_photos(photos, 1.2)
    msg = str(exc.value)
    assert "empty.jpg: empty file (0 bytes)" in msg and "empty2.JPG: empty file" in msg
    assert "text.png" in msg and "anim.jpg" in msg and "GIF" in msg
    assert "4 unusable photo(s)" in msg
