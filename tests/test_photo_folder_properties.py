"""Property tests of bring-your-own photo folders: any mix of names, suffix cases, sizes,
formats (JPEG, PNG, empty, not an image, truncated, 16-bit) and duplicates gives either the
photos in a defined order or a message naming the file; the folder is never changed."""

from __future__ import annotations

import hashlib
import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from PIL import Image

from scenebot.sfm.photofiles import photo_files, photo_order
from scenebot.sfm.photos import PhotoError, check_photos, photos_from_folder

PHOTO_SUFFIXES = [".jpg", ".JPG", ".Jpg", ".jpeg", ".JPEG", ".png", ".PNG", ".pNg"]
OTHER_SUFFIXES = [".txt", ".gif", ".tif", ".heic", ".jpg.bak", ""]
GOOD = ("jpeg", "png_rgb", "png_l", "png_rgba", "png_p")
BAD = ("empty", "text", "gif", "truncated", "png_16bit")

STEMS = st.one_of(
    st.sampled_from(["IMG_0001", "img2", "img10", "0007", "photo 3", "a", "B", "x.y", "ü"]),
    st.text(
        alphabet=st.characters(
            codec="utf-8", exclude_characters="/\\\x00", exclude_categories=["Cs", "Cc"]
        ),
        min_size=1,
        max_size=8,
    ),
)
ENTRY = st.tuples(
    STEMS,
    st.one_of(st.sampled_from(PHOTO_SUFFIXES), st.sampled_from(OTHER_SUFFIXES)),
    st.sampled_from([False, False, False, True]),  # hidden (the name starts with a dot)
    st.sampled_from((*GOOD, *GOOD, *GOOD, *BAD, "duplicate")),
    st.sampled_from([(16, 12), (12, 16), (24, 24), (9, 7)]),
    st.integers(0, 2**16),
)


def _image(kind: str, size: tuple[int, int], seed: int) -> Image.Image:
    rgb = np.random.default_rng(seed).integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
    img = Image.fromarray(rgb)
    mode = {"png_l": "L", "png_rgba": "RGBA", "png_p": "P"}.get(kind)
    return img.convert(mode) if mode else img


def _content(kind: str, size: tuple[int, int], seed: int) -> bytes:
    buf = io.BytesIO()
    if kind == "empty":
        return b""
    if kind == "text":
        return f"not a photo {seed}\n".encode()
    if kind == "png_16bit":
        gray = np.random.default_rng(seed).integers(0, 65535, size[::-1], dtype=np.uint16)
        Image.fromarray(gray).save(buf, "PNG")
        return buf.getvalue()
    if kind == "gif":
        _image("jpeg", size, seed).save(buf, "GIF")
        return buf.getvalue()
    if kind in ("jpeg", "truncated"):
        _image("jpeg", size, seed).save(buf, "JPEG", quality=90)
        data = buf.getvalue()
        return data[: len(data) // 2] if kind == "truncated" else data
    _image(kind, size, seed).save(buf, "PNG")
    return buf.getvalue()


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}


def _is_photo_name(name: str) -> bool:  # the rule, written out independently
    return not name.startswith(".") and name.lower().endswith((".jpg", ".jpeg", ".png"))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(entries=st.lists(ENTRY, min_size=0, max_size=10))
def test_any_photo_folder_gives_ordered_photos_or_names_the_file(entries):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "my photos"
        folder.mkdir()
        written: dict[str, bytes] = {}
        for stem, suffix, hidden, kind, size, seed in entries:
            name = ("." if hidden else "") + stem + suffix
            if name in (".", "..") or name in written or len(name.encode()) > 200:
                continue
            if kind == "duplicate":
                if not written:
                    continue
                data = list(written.values())[seed % len(written)]
            else:
                data = _content(kind, size, seed)
            (folder / name).write_bytes(data)
            written[name] = data
        before = _digest(folder)

        photo_names = [n for n in written if _is_photo_name(n)]
        ordered = sorted(photo_names, key=photo_order)
        assert [p.name for p in photo_files(folder)] == ordered  # the workflow's inputs
        # the reader: the same files and order, a later copy of the same bytes left out
        kept, seen = [], set()
        for n in ordered:
            data = written[n]
            if data and data in seen:
                continue
            seen.add(data)
            kept.append(n)
        try:
            root, photos = photos_from_folder(folder)
            assert [p.name for p in photos] == kept
            check_photos(photos, 1.2)
        except PhotoError as exc:
            msg = str(exc)
            bad = [n for n in kept if _content_kind(written[n]) in BAD]
            event("refused: fewer than 3 photos" if len(kept) < 3 else "refused: a bad file")
            if len(kept) < 3:
                assert "at least 3 photos" in msg and all(n in msg for n in kept), msg
            else:
                assert bad, msg
                for n in bad:
                    assert n in msg, (n, msg)
                assert f"{len(bad)} unusable photo(s)" in msg
        else:
            event("accepted")
            assert root == folder.resolve()
            assert [p.name for p in photos] == sorted((p.name for p in photos), key=photo_order)
            assert len({written[p.name] for p in photos}) == len(photos)  # no duplicates
            assert all(p.width > 0 and p.height > 0 and p.focal_px for p in photos)
            assert not [n for n in kept if _content_kind(written[n]) in BAD]
        assert _digest(folder) == before  # photos are never modified


def _content_kind(data: bytes) -> str:
    """What a file's bytes are (an independent look: magic numbers, not PIL)."""
    if not data:
        return "empty"
    if data.startswith(b"\xff\xd8"):
        return "jpeg" if data.endswith(b"\xff\xd9") else "truncated"
    if data.startswith(b"\x89PNG"):
        return "png_16bit" if data[24] == 16 else "png"  # IHDR bit depth
    if data.startswith(b"GIF"):
        return "gif"
    return "text"


@pytest.mark.parametrize("kind", BAD)
def test_each_bad_kind_is_named(tmp_path, kind):
    for i in range(3):
        (tmp_path / f"p{i}.jpg").write_bytes(_content("jpeg", (16, 12), i))
    (tmp_path / "bad.JPG").write_bytes(_content(kind, (16, 12), 9))
    _, photos = photos_from_folder(tmp_path)
    with pytest.raises(PhotoError, match=r"bad\.JPG"):
        check_photos(photos, 1.2)
