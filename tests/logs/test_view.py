"""``drivewm view``: the Rerun recording, loaded back, holds the drive's entities and rows."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.cli import main


def _chunks(path):
    from rerun.chunk import RrdReader

    return list(RrdReader(path).stream().collect().stream())


def _rows(chunks, entity: str, column: str, static: bool) -> list:
    """All values of ``column`` logged to ``entity`` (static or on the timeline)."""
    values = []
    for ch in chunks:
        rb = ch.to_record_batch()
        if ch.entity_path == entity and ch.is_static == static and column in rb.schema.names:
            values += rb.column(column).to_pylist()
    return values


@pytest.fixture(scope="module")
def recording(tmp_path_factory, synthetic_mcap):
    out = tmp_path_factory.mktemp("view") / "drive.rrd"
    assert main(["view", synthetic_mcap, "--out", str(out)]) == 0
    return _chunks(out)


def test_cameras_are_pinholes_on_the_ego(recording, synthetic_log):
    for cam in synthetic_log.rig.cameras:
        entity = f"/world/ego/{cam.name}"
        (K_colmajor,) = _rows(recording, entity, "Pinhole:image_from_camera", static=True)
        np.testing.assert_allclose(np.array(K_colmajor[0]).reshape(3, 3).T, cam.K, rtol=1e-6)
        assert _rows(recording, entity, "Pinhole:resolution", static=True) == [[[cam.width, cam.height]]]
        (t,) = _rows(recording, entity, "Transform3D:translation", static=True)
        np.testing.assert_allclose(t[0], cam.T_ego_from_cam[:3, 3], rtol=1e-6)


def test_images_per_tick_are_the_logged_bytes(recording, synthetic_log):
    for name, frames in synthetic_log.images.items():
        blobs = _rows(recording, f"/world/ego/{name}", "EncodedImage:blob", static=False)
        times = _rows(recording, f"/world/ego/{name}", "log_time", static=False)
        assert len(blobs) == len(frames) == 6
        assert [bytes(b[0]) for b in blobs] == [f.data for f in frames]
        assert [t.value for t in times] == [f.timestamp_ns for f in frames]  # the log's time, not the wall clock


def test_one_timeline_the_logs_own(recording):
    timelines = {tuple(ch.timeline_names) for ch in recording if not ch.is_static and ch.entity_path != "/__properties"}
    assert timelines == {("log_time",)}  # no wall-clock log_time/log_tick from Rerun itself


def test_ego_trajectory_agents_and_road(recording, synthetic_log):
    poses = _rows(recording, "/world/ego", "Transform3D:translation", static=False)
    assert len(poses) == 5  # 6 ticks, the NaN gap skipped
    (strips,) = _rows(recording, "/world/ego_trajectory", "LineStrips3D:strips", static=True)
    assert [len(s) for s in strips] == [3, 2]  # split at the gap
    np.testing.assert_allclose(strips[1][-1], synthetic_log.T_world_from_ego[5, :3, 3], rtol=1e-6)
    labels = _rows(recording, "/world/agents", "Boxes3D:labels", static=False)
    assert labels == [["car:car-1", "truck:truck-7"]] * 6
    half = _rows(recording, "/world/agents", "Boxes3D:half_sizes", static=False)
    np.testing.assert_allclose(half[0][1], [6.0, 1.25, 1.6], rtol=1e-6)
    (edges,) = _rows(recording, "/world/road/road_edge", "LineStrips3D:strips", static=True)
    assert len(edges) == 2 and len(edges[0]) == 9
    np.testing.assert_allclose(edges[1], synthetic_log.road[4].points_xyz, rtol=1e-6)
    (surface,) = _rows(recording, "/world/road/road_surface", "LineStrips3D:strips", static=True)
    outline = synthetic_log.road[5].points_xyz
    np.testing.assert_allclose(surface[0], np.concatenate([outline, outline[:1]]), rtol=1e-6)  # drawn closed
    (static,) = _rows(recording, "/world/static", "Boxes3D:labels", static=True)
    assert static == ["building:bldg0", "pole:pole1"]
    (centers,) = _rows(recording, "/world/static", "Boxes3D:centers", static=True)
    np.testing.assert_allclose(centers[0], synthetic_log.static[0].center_xyz, rtol=1e-6)
    (text,) = _rows(recording, "/scene", "TextDocument:text", static=True)
    assert "**weather**: snow" in text[0] and "a synthetic snowy drive" in text[0]


def test_view_of_a_bad_file_is_one_line_error(tmp_path, capsys):
    (tmp_path / "x.mcap").write_bytes(b"not mcap at all")
    assert main(["view", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"error: {tmp_path / 'x.mcap'}: not an MCAP file (bad magic bytes)"
    assert not (tmp_path / "x.rrd").exists()


def test_view_out_that_cannot_be_written_is_one_line_error(tmp_path, capsys, synthetic_mcap):
    """An --out that is a folder, lies under a file, or is the log itself is refused before any work:
    the first two had ended in an IsADirectoryError / FileExistsError traceback, the last had replaced
    the drive log with its recording."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("kept")
    log = tmp_path / "drive.mcap"
    log.write_bytes(open(synthetic_mcap, "rb").read())
    for out, message in [
        (tmp_path / "folder", f"{tmp_path / 'folder'}: is a folder, not a file"),
        (tmp_path / "file" / "x.rrd", f"{tmp_path / 'file'}: {tmp_path / 'file'} is a file, not a folder"),
        (log, f"{log}: is the drive log being read; write the recording elsewhere"),
    ]:
        assert main(["view", str(log), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and err.endswith(message) and "Traceback" not in err
    assert (tmp_path / "file").read_text() == "kept" and list((tmp_path / "folder").iterdir()) == []
    assert log.read_bytes() == open(synthetic_mcap, "rb").read()


def test_view_says_why_a_log_gave_no_ego_poses(tmp_path, capsys, synthetic_mcap):
    """A topic map naming a world frame the log lacks had given a recording with 0 poses and no word
    why; the warning names the frames looked for and the ones the log has."""
    tmap = tmp_path / "map.yaml"
    tmap.write_text("world_frame: odom\n")
    out = tmp_path / "drive.rrd"
    assert main(["view", synthetic_mcap, "--out", str(out), "--topic-map", str(tmap)]) == 0
    captured = capsys.readouterr()
    assert " 0 poses" in captured.out
    (line,) = [x for x in captured.err.splitlines() if "no ego poses" in x]
    assert "from world frame 'odom' to ego frame 'ego'" in line and "world" in line.split("frames: ")[1]
    assert _rows(_chunks(out), "/world/ego", "Transform3D:translation", static=False) == []
    assert main(["view", synthetic_mcap, "--out", str(out)]) == 0  # the log's own frames: poses, no warning
    assert "no ego poses" not in capsys.readouterr().err
