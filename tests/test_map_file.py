"""Nav2 map files (amr_common.world.map_file): map_server's reading, map_saver's writing, bad ones.

The images here are written byte by byte (PGM) or with Pillow (PNG), not by map_file, so the
reader is checked against the format, not against its own writer.
"""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from amr_common.world.map_file import MapFileError, read_map, trinary_pixels, write_map
from amr_common.world.map_raster import Raster
from amr_common.world.world import WORLDS_DIR, World, WorldError

NAV2_YAML = ("image: {image}\nmode: {mode}\nresolution: {resolution}\norigin: {origin}\n"
             "negate: {negate}\noccupied_thresh: {occupied}\nfree_thresh: {free}\n")


def pgm(path, pixels, maxval=255, comment=b"# CREATOR: a test\n"):
    """A binary (P5) PGM of a (rows, cols) array, row 0 = top, as map_saver writes it."""
    rows, cols = np.shape(pixels)
    data = np.asarray(pixels, dtype=">u2" if maxval > 255 else np.uint8).tobytes()
    path.write_bytes(b"P5\n" + comment + f"{cols} {rows}\n{maxval}\n".encode() + data)
    return path


def map_yaml(tmp_path, image="map.pgm", name="map.yaml", extra="", **fields):
    values = dict(image=image, mode="trinary", resolution=0.05, origin="[-1.0, 2.0, 0]",
                  negate=0, occupied=0.65, free=0.196)
    values.update(fields)
    path = tmp_path / name
    path.write_text(NAV2_YAML.format(**values) + extra)
    return path


# The image, top row first. Trinary with occupied 0.65 / free 0.196:
#   0 -> p 1 -> 100;  254 -> p 0.004 -> 0;  205 -> p 0.19608 -> -1 (just above 0.196)
#   89 -> p 0.65098 -> 100;  90 -> p 0.647 -> -1;  200 -> p 0.2157 -> -1
PIXELS = np.array([[0, 254, 205], [89, 90, 200], [254, 254, 254]], dtype=np.uint8)
TRINARY = np.array([[0, 0, 0], [100, -1, -1], [100, 0, -1]])  # raster rows: bottom first


def test_trinary_reading_follows_map_server_and_flips_the_rows(tmp_path):
    pgm(tmp_path / "map.pgm", PIXELS)
    spec = read_map(map_yaml(tmp_path))
    assert spec.raster.values.dtype == np.int8
    np.testing.assert_array_equal(spec.raster.values, TRINARY)
    assert spec.raster.resolution == 0.05 and spec.raster.origin == (-1.0, 2.0)
    # Image row 0 is the top: the black pixel (top left) is the cell at the top left.
    assert spec.raster.cell_of(-1.0 + 0.025, 2.0 + 2.5 * 0.05) == (2, 0)
    assert spec.mode == "trinary" and spec.image_path == tmp_path / "map.pgm"


def test_negate_reads_white_as_occupied(tmp_path):
    pgm(tmp_path / "map.pgm", PIXELS)
    # p = v / 255: 0 -> 0 (free), 254 -> 0.996, 205 -> 0.804, 200 -> 0.784 (occupied),
    # 89 -> 0.349, 90 -> 0.353 (unknown)
    values = read_map(map_yaml(tmp_path, negate=1)).raster.values
    np.testing.assert_array_equal(values, [[100, 100, 100], [-1, -1, 100], [0, 100, 100]])
    assert (read_map(map_yaml(tmp_path, negate="true")).raster.values == values).all()


def test_thresholds_are_inclusive_as_in_navigation2_jazzy(tmp_path):
    # p of pixel 51 in float32 (map_server's arithmetic) is 0.8 as a float32: at the threshold.
    p51 = float(np.float32(1.0) - np.float32(51) / np.float32(255.0))
    p200 = float(np.float32(1.0) - np.float32(200) / np.float32(255.0))
    pgm(tmp_path / "map.pgm", [[51, 200, 254]])
    values = read_map(map_yaml(tmp_path, occupied=repr(p51), free=repr(p200))).raster.values
    np.testing.assert_array_equal(values, [[100, 0, 0]])  # p >= occupied, p <= free
    nudged = read_map(map_yaml(tmp_path, occupied=repr(p51 + 1e-6),
                               free=repr(p200 - 1e-6))).raster.values
    np.testing.assert_array_equal(nudged, [[-1, -1, 0]])


def test_png_reads_like_pgm_and_transparent_pixels_are_unknown(tmp_path):
    pgm(tmp_path / "map.pgm", PIXELS)
    Image.fromarray(PIXELS, mode="L").save(tmp_path / "gray.png")
    from_pgm = read_map(map_yaml(tmp_path)).raster.values
    from_png = read_map(map_yaml(tmp_path, image="gray.png", name="png.yaml")).raster.values
    np.testing.assert_array_equal(from_png, from_pgm)
    alpha = np.full(PIXELS.shape, 255, dtype=np.uint8)
    alpha[0, 0] = 254  # the black top-left pixel, barely transparent
    Image.fromarray(np.dstack([PIXELS, alpha]), mode="LA").save(tmp_path / "alpha.png")
    values = read_map(map_yaml(tmp_path, image="alpha.png", name="alpha.yaml")).raster.values
    expected = TRINARY.copy()
    expected[2, 0] = -1
    np.testing.assert_array_equal(values, expected)


def test_colour_plain_and_16_bit_images(tmp_path):
    rgb = np.zeros((1, 3, 3), dtype=np.uint8)
    rgb[0, 1] = 255  # white: free
    rgb[0, 2] = (255, 0, 0)  # red: luma 76 -> p 0.70 -> occupied
    Image.fromarray(rgb, mode="RGB").save(tmp_path / "rgb.png")
    values = read_map(map_yaml(tmp_path, image="rgb.png")).raster.values
    np.testing.assert_array_equal(values, [[100, 0, 100]])
    (tmp_path / "plain.pgm").write_text("P2\n# plain\n3 1\n255\n0 254 205\n")
    values = read_map(map_yaml(tmp_path, image="plain.pgm")).raster.values
    np.testing.assert_array_equal(values, [[100, 0, -1]])
    pgm(tmp_path / "wide.pgm", [[0, 65535, 205 * 257]], maxval=65535)
    values = read_map(map_yaml(tmp_path, image="wide.pgm")).raster.values
    np.testing.assert_array_equal(values, [[100, 0, -1]])


def test_scale_and_raw_modes(tmp_path):
    pgm(tmp_path / "map.pgm", [[0, 254, 160, 205]])
    values = read_map(map_yaml(tmp_path, mode="scale")).raster.values
    # 160: p = 95/255 = 0.3725, between the thresholds: round(100 (p - 0.196) / 0.454) = 39
    np.testing.assert_array_equal(values, [[100, 0, 39, 0]])  # 205: 0.196078 -> rounds to 0
    pgm(tmp_path / "raw.pgm", [[0, 50, 100, 101, 255]])
    values = read_map(map_yaml(tmp_path, image="raw.pgm", mode="raw")).raster.values
    np.testing.assert_array_equal(values, [[0, 50, 100, -1, -1]])


def test_map_savers_old_free_thresh_reads_unknown_as_free_as_map_server_does(tmp_path, caplog):
    """Before navigation2 1.3.7 map_saver wrote free_thresh 0.25 with 205 for unknown."""
    pgm(tmp_path / "map.pgm", [[0, 254, 205]])
    values = read_map(map_yaml(tmp_path, free=0.25)).raster.values
    np.testing.assert_array_equal(values, [[100, 0, 0]])
    assert "reads map_saver's unknown pixels (205) as free" in caplog.text
    caplog.clear()
    read_map(map_yaml(tmp_path))
    assert "205" not in caplog.text


def test_read_map_refuses_a_world_yaml():
    with pytest.raises(MapFileError, match="not a Nav2 map YAML"):
        read_map(WORLDS_DIR / "lab02.yaml")


def test_project_keys_are_read_and_other_keys_ignored(tmp_path):
    pgm(tmp_path / "map.pgm", np.full((20, 20), 254, dtype=np.uint8))
    extra = ("name: room\nstarts:\n  middle: [-0.5, 2.5, pi/2]\ngoals:\n  corner: [-0.8, 2.8]\n"
             "cell_size: 0.2\nsome_other_tool: 3\n")
    spec = read_map(map_yaml(tmp_path, extra=extra))
    assert spec.name == "room" and spec.cell_size == 0.2
    assert spec.starts == {"middle": (-0.5, 2.5, pytest.approx(np.pi / 2))}
    assert spec.goals == {"corner": (-0.8, 2.8)} and spec.goal == (-0.8, 2.8)
    world = World.load(tmp_path / "map.yaml")
    assert world.name == "room" and world.resolve_start("middle")[:2] == (-0.5, 2.5)


def test_absolute_image_path_and_default_mode(tmp_path):
    image = pgm(tmp_path / "elsewhere.pgm", [[254, 0]])
    path = tmp_path / "sub" / "map.yaml"
    path.parent.mkdir()
    path.write_text(f"image: {image}\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n"
                    f"occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    spec = read_map(path)
    assert spec.mode == "trinary" and spec.image_path == image
    np.testing.assert_array_equal(spec.raster.values, [[0, 100]])


# --- writing -------------------------------------------------------------------------------

@pytest.mark.parametrize("image_format", ["pgm", "png"])
def test_written_maps_read_back_cell_for_cell(tmp_path, image_format):
    rng = np.random.default_rng(4)
    values = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(37, 53))
    raster = Raster(values, 0.025, (-3.2125, 1.05))
    yaml_path, image_path = write_map(raster, tmp_path / "new" / "saved", image_format,
                                      extras={"starts": {"a": (1.0, 2.0, 0.5)}})
    assert (yaml_path.name, image_path.name) == ("saved.yaml", f"saved.{image_format}")
    spec = read_map(yaml_path)
    np.testing.assert_array_equal(spec.raster.values, values)
    assert spec.raster.resolution == 0.025 and spec.raster.origin == (-3.2125, 1.05)
    assert spec.starts == {"a": (1.0, 2.0, 0.5)}


def test_written_files_are_map_savers(tmp_path):
    values = np.array([[0, 100, -1], [10, 25, 26], [64, 65, 127]], dtype=np.int8)
    yaml_path, image_path = write_map(Raster(values, 0.05, (0.0, 0.0)), tmp_path / "m.yaml")
    text = yaml_path.read_text().splitlines()
    assert text[:7] == ["image: m.pgm", "mode: trinary", "resolution: 0.05",
                        "origin: [0, 0, 0]", "negate: 0", "occupied_thresh: 0.65",
                        "free_thresh: 0.196"]
    data = image_path.read_bytes()
    assert data.startswith(b"P5\n")
    pixels = np.frombuffer(data[-9:], dtype=np.uint8).reshape(3, 3)
    # Top row first; 0..25 free (254), 65..100 occupied (0), the rest unknown (205).
    np.testing.assert_array_equal(pixels, [[205, 0, 205], [254, 254, 205], [254, 0, 205]])
    np.testing.assert_array_equal(trinary_pixels(values)[::-1], pixels)


def test_an_interrupted_save_keeps_the_previous_map(tmp_path, monkeypatch):
    old = Raster(np.zeros((4, 4), dtype=np.int8), 0.05, (0.0, 0.0))
    yaml_path, image_path = write_map(old, tmp_path / "m")
    before = (yaml_path.read_bytes(), image_path.read_bytes())
    import amr_common.world.map_file as map_file

    def broken(stream, *args):
        stream.write(b"P5\n")
        raise KeyboardInterrupt  # Ctrl-C in the middle of the image

    monkeypatch.setattr(map_file, "_write_image", broken)
    new = Raster(np.full((8, 8), 100, dtype=np.int8), 0.05, (0.0, 0.0))
    with pytest.raises(KeyboardInterrupt):
        write_map(new, tmp_path / "m")
    assert (yaml_path.read_bytes(), image_path.read_bytes()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pgm", "m.yaml"]


# --- bad input -----------------------------------------------------------------------------

def _refused(path, message, error=MapFileError):
    with pytest.raises(error) as info:
        World.load(path)
    assert isinstance(info.value, WorldError)  # every --world check reports it in one line
    assert str(path) in str(info.value) and message in str(info.value), str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "negate", "occupied_thresh",
                                 "free_thresh"])
def test_missing_keys_are_refused(tmp_path, key):
    pgm(tmp_path / "map.pgm", PIXELS)
    path = map_yaml(tmp_path)
    path.write_text("\n".join(line for line in path.read_text().splitlines()
                              if not line.startswith(key + ":")) + "\n")
    _refused(path, f"missing key(s) {key}")


@pytest.mark.parametrize("fields, message", [
    ({"resolution": "abc"}, "resolution must be a number"),
    ({"resolution": 0}, "resolution must be > 0"),
    ({"resolution": -0.05}, "resolution must be > 0"),
    ({"resolution": ".nan"}, "resolution is not finite"),
    ({"origin": "[0, zero, 0]"}, "origin y must be a number"),
    ({"origin": "[0, 0]"}, "origin must be [x, y, yaw]"),
    ({"origin": "[0, 0, 0.3]"}, "origin yaw 0.3 rad is not supported"),
    ({"free": 0.65}, "free_thresh < occupied_thresh"),
    ({"free": 0.7}, "free_thresh < occupied_thresh"),
    ({"occupied": 1.5}, "<= 1"),
    ({"free": "low"}, "free_thresh must be a number"),
    ({"negate": "maybe"}, "negate must be 0, 1, true or false"),
    ({"mode": "colour"}, "mode must be one of trinary, scale, raw"),
    ({"image": "''"}, "'image' must be a file name"),
])
def test_malformed_fields_are_refused(tmp_path, fields, message):
    pgm(tmp_path / "map.pgm", PIXELS)
    _refused(map_yaml(tmp_path, **fields), message)


def test_missing_unreadable_huge_and_all_wall_images_are_refused(tmp_path):
    _refused(map_yaml(tmp_path, image="nowhere.pgm"), "nowhere.pgm not found")
    (tmp_path / "junk.pgm").write_bytes(b"this is no image")
    _refused(map_yaml(tmp_path, image="junk.pgm"), "is not a readable PGM/PNG image")
    pgm(tmp_path / "cut.pgm", PIXELS)
    (tmp_path / "cut.pgm").write_bytes((tmp_path / "cut.pgm").read_bytes()[:-4])
    _refused(map_yaml(tmp_path, image="cut.pgm"), "is not a readable PGM/PNG image")
    # 5000 x 4000 pixels declared (20 M cells): refused from the header, nothing allocated.
    (tmp_path / "huge.pgm").write_bytes(b"P5\n5000 4000\n255\n" + b"\xfe" * 100)
    _refused(map_yaml(tmp_path, image="huge.pgm"), "5,000 x 4,000 = 20,000,000 cells")
    pgm(tmp_path / "walls.pgm", np.zeros((5, 5), dtype=np.uint8))
    _refused(map_yaml(tmp_path, image="walls.pgm"), "the map has no free cell")


def test_broken_yaml_is_a_one_line_error(tmp_path):
    path = tmp_path / "map.yaml"
    path.write_text("image: map.pgm\nresolution: [0.05\norigin: [0, 0, 0]\n")
    _refused(path, "invalid YAML: while parsing a flow sequence", WorldError)


def test_a_named_start_off_the_free_cells_is_refused_when_used_and_another_start_overrides_it(
        tmp_path):
    # A coarse SLAM map's own start could make the whole map unreadable, --start included.
    pgm(tmp_path / "map.pgm", np.full((20, 20), 254, dtype=np.uint8))
    world = World.load(map_yaml(tmp_path, extra="starts:\n  out: [5.0, 5.0, 0]\n"))
    for start in ("out", None):
        with pytest.raises(WorldError, match=r"start 'out' \(5, 5\) is outside the map: give a "
                                             r"start pose \(x, y, theta\)"):
            world.resolve_start(start)
    assert world.resolve_start((-0.5, 2.5, 0.0)) == (-0.5, 2.5, 0.0)


def test_extras_of_scalars_only_stay_a_valid_map_yaml(tmp_path):
    """Extras of scalars only (a name and a description) stay block-style YAML.

    They were dumped as one flow mapping line after the Nav2 keys: invalid YAML, the saved map
    could not be read back.
    """
    values = np.zeros((6, 6), dtype=np.int8)
    values[0, :] = 100
    yaml_path, _ = write_map(Raster(values, 0.05, (0.0, 0.0)), tmp_path / "m",
                             extras={"name": "room", "description": "SLAM map: seed 0"})
    spec = read_map(yaml_path)
    assert spec.name == "room" and spec.description == "SLAM map: seed 0"
    assert np.array_equal(spec.raster.values, values)
    yaml_path, _ = write_map(Raster(values, 0.05, (0.0, 0.0)), tmp_path / "n", extras={
        "name": "room", "grid_origin": [0.0, 0.1], "starts": {"a": [0.1, 0.1, 0.0]}})
    spec = read_map(yaml_path)
    assert spec.grid_origin == (0.0, 0.1) and spec.starts == {"a": (0.1, 0.1, 0.0)}
