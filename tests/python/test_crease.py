"""The Python module against the command line: the same curves, to the bit, from the same points;
laspy and structured arrays in; a resumable run stopped and resumed; the errors' types and
messages; outputs written and read back."""

import json
import signal
import subprocess
import sys
import threading
import time

import crease
import laspy
import numpy as np
import pytest


def assert_same_curves(a, b):
    """The same curves: ids, closed flags, positions and normals to the bit, corners,
    confidences, shapes."""
    assert len(a) == len(b) > 0
    for x, y in zip(a, b):
        assert (x.id, x.closed, x.shape) == (y.id, y.closed, y.shape)
        assert np.array_equal(x.points, y.points), f"curve {x.id}: positions differ"
        assert np.array_equal(x.normals, y.normals), f"curve {x.id}: normals differ"
        assert np.array_equal(x.corner, y.corner), f"curve {x.id}: corners differ"
        assert x.confidence == y.confidence


def cli_curves(cli, las, out, *args):
    cli("extract", las, "-o", out, "-q", *args)
    return crease.read(out)


@pytest.mark.parametrize("name", ["cube", "fandisk"])
def test_extract_gives_the_command_lines_curves_to_the_bit(name, cli, cube_las, fixtures, tmp_path):
    las = cube_las if name == "cube" else fixtures / "fandisk.las"
    expected = cli_curves(cli, las, tmp_path / "cli")
    # A laspy object in, scaled as crease scales the file.
    from_laspy = crease.extract(laspy.read(las))
    assert_same_curves(from_laspy, expected)
    # The same points as an (N, 3) array, and as a structured array with X, Y, Z (a PDAL
    # pipeline's array).
    data = laspy.read(las)
    xyz = np.column_stack([np.asarray(data.x), np.asarray(data.y), np.asarray(data.z)])
    assert_same_curves(crease.extract(xyz), expected)
    pdal_like = np.zeros(len(xyz), dtype=[("X", "f8"), ("Y", "f8"), ("Z", "f8"), ("Intensity", "u2")])
    pdal_like["X"], pdal_like["Y"], pdal_like["Z"] = xyz.T
    assert_same_curves(crease.extract(pdal_like), expected)
    # The report is the run's, and each curve's attributes are the GeoJSON's.
    report = json.loads((tmp_path / "cli" / "report.json").read_text())
    assert from_laspy.report["params"] == report["params"]
    features = json.loads((tmp_path / "cli" / "curves.geojson").read_text())["features"]
    assert [c.attributes for c in from_laspy] == [f["properties"] for f in features]


def test_the_curves_are_the_same_at_any_thread_count(fixtures):
    pts = crease._as_points(laspy.read(fixtures / "fandisk.las"))
    assert_same_curves(crease.extract(pts, threads=1), crease.extract(pts, threads=2))


def test_parameters_and_output_settings_are_the_command_lines(cli, cube_las, tmp_path):
    expected = cli_curves(cli, cube_las, tmp_path / "cli", "--outside", "up", "--min-angle", "40", "--min-length", "0.5")
    got = crease.extract(laspy.read(cube_las), outside="up", min_angle=40, min_length=0.5)
    assert_same_curves(got, expected)
    assert "convex" in {c.shape for c in got}
    # Scanner positions as an array, as --outside takes them as text.
    expected = cli_curves(cli, cube_las, tmp_path / "cli2", "--outside", "0.5,0.5,5")
    assert_same_curves(crease.extract(laspy.read(cube_las), outside=np.array([[0.5, 0.5, 5.0]])), expected)


def test_label_points_writes_the_command_lines_labelled_copy(cli, cube_las, tmp_path):
    cli("extract", cube_las, "-o", tmp_path / "cli", "-q", "--label-points")
    run = crease.extract_file(str(cube_las), str(tmp_path / "py"), label_points=True)
    assert [p.name for p in run.labels] == ["cube.laz"]
    got, expected = laspy.read(run.labels[0]), laspy.read(tmp_path / "cli" / "labels" / "cube.laz")
    source = laspy.read(cube_las)
    assert len(got.points) == len(source.points)
    assert np.array_equal(got.x, source.x) and np.array_equal(got.z, source.z)
    for name in ("edge_distance", "curve_id", "edge"):
        assert np.array_equal(got[name], expected[name]), name
    assert 0 < int(np.sum(got["edge"])) < len(got.points)
    # Without the keyword, a finished run removes its copies.
    assert crease.extract_file(str(cube_las), str(tmp_path / "py")).labels == []
    assert not (tmp_path / "py" / "labels").exists()


def test_the_interpreter_is_free_while_extract_runs(fixtures):
    pts = crease._as_points(laspy.read(fixtures / "fandisk.las"))
    done, ticks = threading.Event(), 0
    worker = threading.Thread(target=lambda: (crease.extract(pts), done.set()))
    start = time.monotonic()
    worker.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.002)
    worker.join()
    seconds = time.monotonic() - start
    # (Held by the extraction, the interpreter would let this loop tick only before and after it.)
    assert ticks > 0.25 * seconds / 0.002, f"{ticks} ticks in {seconds:.2f} s"


def test_an_interrupted_run_resumes_to_the_same_curves(cube_las, tmp_path):
    # (A small budget makes several tiles, so the run is stopped between them.)
    whole = crease.extract_file(cube_las, tmp_path / "whole", memory="8M", progress=False)
    assert whole.report["tiles"] > 1 and not whole.report["resumed"]
    seen = []

    def stop_after_bucketing(stage, done, total, unit):
        seen.append((stage, done, total, unit))
        if stage != "bucketing":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        crease.extract_file(cube_las, tmp_path / "run", memory="8M", progress=stop_after_bucketing)
    # (The callback is polled: a small cloud may be bucketed before it is first called, so
    # only the stage it stopped in is known: one after bucketing.)
    assert seen and seen[-1][0] != "bucketing"
    assert (tmp_path / "run" / "manifest.json").is_file()
    assert not (tmp_path / "run" / "curves.ply").exists()
    run = crease.extract_file([cube_las], tmp_path / "run", memory="8M", progress=False)
    assert run.report["resumed"] is True
    assert run.report["pass_seconds"]["bucketing"] == 0
    assert_same_curves(run.curves(), whole.curves())
    assert_same_curves(crease.read(tmp_path / "run"), whole.curves())


def test_ctrl_c_stops_a_run_within_a_second_and_the_same_call_resumes_it(cli, tmp_path):
    las = tmp_path / "cube.las"
    cli("synth", "shape", "cube", "-n", "400000", "-o", las)
    script = (
        "import sys, crease\n"
        "crease.extract_file(sys.argv[1], sys.argv[2], memory='16M', progress=lambda s, d, t, u: print(s, flush=True))\n"
    )
    p = subprocess.Popen([sys.executable, "-c", script, str(las), str(tmp_path / "run")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in p.stdout:
        if line.strip() == "residuals":
            break
    sent = time.monotonic()
    p.send_signal(signal.SIGINT)
    p.wait(timeout=60)
    seconds = time.monotonic() - sent
    stderr = p.stderr.read()
    assert p.returncode != 0 and "KeyboardInterrupt" in stderr, stderr
    print(f"stopped {seconds:.2f} s after Ctrl-C")
    assert seconds < 1.0, f"stopped {seconds:.2f} s after Ctrl-C"
    assert not (tmp_path / "run" / "curves.ply").exists()
    run = crease.extract_file(las, tmp_path / "run", memory="16M", progress=False)
    assert run.report["resumed"] is True and run.report["counts"]["curves"] == 12


def test_bad_input_raises_input_error_naming_the_file_as_the_command_line_does(cli, crease_bin, fixtures, tmp_path):
    truncated = tmp_path / "truncated.las"
    truncated.write_bytes((fixtures / "cube.las").read_bytes()[:3000])
    with pytest.raises(crease.InputError) as e:
        crease.extract_file(truncated, tmp_path / "run", progress=False)
    assert isinstance(e.value, ValueError)
    assert str(e.value).startswith(str(truncated)) and e.value.filename == str(truncated)
    p = subprocess.run([str(crease_bin), "extract", str(truncated), "-o", str(tmp_path / "cli"), "-q"], capture_output=True, text=True)
    assert p.returncode == 65 and p.stderr.strip() == f"crease: error: {e.value}"
    missing = tmp_path / "missing.las"
    with pytest.raises(crease.InputError, match="missing.las"):
        crease.extract_file(missing, tmp_path / "run2", progress=False)
    with pytest.raises(crease.InputError, match="not finite"):
        crease.extract(np.array([[0.0, 0.0, 0.0], [np.nan, 1.0, 2.0]] * 10))
    with pytest.raises(crease.InputError, match=r"\(N, 3\)"):
        crease.extract(np.zeros((10, 2)))
    with pytest.raises(crease.InputError, match="no points"):
        crease.extract(np.zeros((0, 3)))
    with pytest.raises(crease.InputError, match="not a finished crease run"):
        crease.read(tmp_path)
    with pytest.raises(crease.InputError, match="not a curve file"):
        crease.read(fixtures / "cube.las")


def test_bad_arguments_raise_value_or_type_errors_with_the_command_lines_messages(tmp_path):
    pts = np.random.default_rng(1).random((100, 3))
    with pytest.raises(ValueError, match="--kappa must be a positive number") as e:
        crease.extract(pts, kappa=-1)
    assert not isinstance(e.value, crease.InputError)
    with pytest.raises(ValueError, match="--memory must be at least"):
        crease.extract(pts, memory="1K")
    with pytest.raises(ValueError, match="is not a model"):
        crease.extract(pts, model="cones")
    with pytest.raises(TypeError, match="unexpected keyword argument 'kapa'"):
        crease.extract(pts, kapa=0.1)
    with pytest.raises(TypeError, match="kappa"):
        crease.extract(pts, kappa="small")


def test_curves_write_and_read_back(fixtures, tmp_path):
    curves = crease.extract(laspy.read(fixtures / "fandisk.las"), crs="EPSG:32632")
    assert curves.crs == "EPSG:32632"
    for fmt in ["ply", "obj"]:
        path = curves.write(tmp_path / f"c.{fmt}")
        back = crease.read(path)
        assert [len(c) for c in back] == [len(c) for c in curves]
        assert all(np.array_equal(a.points, b.points) for a, b in zip(curves, back)), fmt
    doc = json.loads(curves.write(tmp_path / "c.geojson").read_text())
    assert doc["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32632"
    assert len(doc["features"]) == len(curves)
    assert doc["features"][0]["geometry"]["coordinates"] == curves[0].points.tolist()
    assert curves.write(tmp_path / "c.gpkg").stat().st_size > 0
    assert curves.write(tmp_path / "pieces", format="json").is_file()
    with pytest.raises(ValueError, match="not a curve format"):
        curves.write(tmp_path / "c.shp")
    with pytest.raises(OSError) as e:
        curves.write(tmp_path / "no" / "such" / "dir" / "c.ply")
    assert "c.ply" in str(e.value) and e.value.filename.endswith("c.ply")
    # Read without their run's report, the curves lack the typed pieces' tolerance until given.
    bare = crease.read(tmp_path / "c.ply")
    assert bare.tolerance is None and bare[0].kind is None
    with pytest.raises(ValueError, match="tolerance"):
        bare.write(tmp_path / "bare.geojson")
    assert crease.read(tmp_path / "c.ply", tolerance=curves.tolerance)[0].kind == curves[0].kind


def test_curves_as_arrays(fixtures):
    curves = crease.extract(laspy.read(fixtures / "fandisk.las"))
    points, ids = curves.to_numpy()
    assert points.shape == (sum(len(c) for c in curves), 3) and points.dtype == np.float64
    assert ids.shape == (len(points),)
    first = curves[0]
    assert np.array_equal(points[ids == first.id], first.points)
    assert first.normals.shape == (len(first), 2, 3) and first.corner.dtype == bool
    assert np.allclose(np.linalg.norm(first.normals, axis=2), 1, atol=1e-5)
    assert curves[-1].id == list(curves)[-1].id
    with pytest.raises(IndexError):
        curves[len(curves)]
    assert {c.kind for c in curves} <= {"line", "arc", "circle", "spline", "polyline", "mixed"}


def test_to_geopandas(fixtures, tmp_path):
    geopandas = pytest.importorskip("geopandas")
    curves = crease.extract(laspy.read(fixtures / "fandisk.las"), crs="EPSG:32632")
    gdf = curves.to_geopandas()
    assert isinstance(gdf, geopandas.GeoDataFrame) and len(gdf) == len(curves)
    assert gdf.crs.to_epsg() == 32632
    assert gdf.geometry.iloc[0].has_z
    assert np.array_equal(np.asarray(gdf.geometry.iloc[0].coords), curves[0].points)
    assert list(gdf["id"]) == [c.id for c in curves]
