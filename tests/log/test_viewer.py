"""`view`: sessions as rerun recordings (the cheap tier: no browser), and what rerun's own MCAP
importer makes of a session file.

Runs where rerun-sdk is installed (the `view` extra, in `dev` on Python >= 3.11); the recordings
are read back with rerun's own RRD reader. The error paths run everywhere.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from viewer_sessions import N_FRAMES, write_full_session, write_platform_session

from layerskin_exp.log import load_session
from layerskin_exp.log.cli import main
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view import rerun_view as V


def _rerun():
    return pytest.importorskip("rerun", reason="rerun-sdk not installed (pip install 'layerskin-exp[view]')")


def _columns(rrd) -> dict[str, dict]:
    """entity -> {column name: [arrow arrays]} of the first recording in an .rrd (rerun's reader)."""
    from rerun.chunk import RrdReader

    out: dict[str, dict] = {}
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        cols = out.setdefault(chunk.entity_path, {})
        for name, col in zip(batch.schema.names, batch.columns, strict=True):
            cols.setdefault(name, []).append(col)
    return out


def _rows(cols: dict, name: str) -> int:
    return sum(len(a) for a in cols[name])


def test_view_save_holds_both_maps_the_wrench_scalars_events_and_a_blueprint(tmp_path, capsys):
    _rerun()
    from rerun.chunk import RrdReader

    session = write_platform_session(tmp_path / "press.mcap")
    out = tmp_path / "press.rrd"
    assert main(["view", str(session), "--save", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    assert RrdReader(out).blueprints(), "no blueprint stored with the recording"
    cols = _columns(out)
    for topic in S.SKIN_TOPICS.values():
        assert _rows(cols[topic], "Image:buffer") == N_FRAMES, topic
    s = load_session(session)
    force = cols[f"{S.WRENCH_TOPIC}/force_n"]
    logged = np.concatenate([a.to_numpy(zero_copy_only=False) for a in force["Scalars:scalars"]])
    np.testing.assert_allclose(np.stack(logged), s.streams["wrench"]["force_n"])
    names = force["SeriesLines:names"][0][0].as_py()
    assert names == ["Fx (F/T)", "Fy (F/T)", "Fz (F/T)"]  # the stored layout's labels
    texts = [t for a in cols[S.EVENTS_TOPIC]["TextLog:text"] for row in a.to_pylist() for t in row]
    assert len(texts) == 2 and texts[1].startswith("phase: press")


def test_the_skin_images_are_the_maps_in_the_layouts_colours():
    maps = np.zeros((2, 16, 16), np.uint16)
    maps[0, 0, 0], maps[1] = 4095, 2000
    rgb = V.skin_rgb(maps)
    assert rgb.shape == (2, 16, 16, 3) and rgb.dtype == np.uint8
    # rows flipped (+y up, as the layout's flip_vertical): row 0 of the map is the bottom row
    assert not np.array_equal(rgb[0, 15, 0], rgb[0, 0, 0]) and np.array_equal(rgb[0, 0, 0], rgb[0, 5, 5])
    assert len({tuple(p) for p in rgb[1].reshape(-1, 3)}) == 1


def test_every_plot_of_the_layout_has_its_data_logged(tmp_path):
    _rerun()
    session = write_full_session(tmp_path / "full.mcap")
    out = tmp_path / "full.rrd"
    assert main(["view", str(session), "--save", str(out)]) == 0
    cols = _columns(out)
    series = V.plot_series(V.session_topics(session))
    assert {f"{S.WRENCH_TOPIC}/force_n", f"{S.STAGE_TOPIC}/position_mm", f"{S.TCP_TOPIC}/pose/position",
            f"{S.GRIPPER_TOPIC}/position_mm"} <= set(series)
    for entity in series:
        assert _rows(cols[entity], "Scalars:scalars") > 0, entity
    assert any(e.startswith(V.RIG_ROOT + "/") and "Transform3D:translation" in c for e, c in cols.items())


def test_plot_paths_map_to_entities_and_columns():
    assert V.parse_series("/ft/wrench.force_n[2]", "Fz") == V.Series("/ft/wrench/force_n", 2, "Fz")
    assert V.parse_series("/arm/tcp.pose.position.y", "y") == V.Series("/arm/tcp/pose/position", 1, "y")
    assert V.parse_series("/skin/summary.deep.total_counts", "d") == V.Series("/skin/summary/deep/total_counts",
                                                                            0, "d")
    with pytest.raises(ValueError, match="not TOPIC.field"):
        V.parse_series("no-topic", "x")


def test_rerun_mcap_importer_decodes_each_session_channel_to_named_fields(tmp_path):
    """rerun's own converter (`rerun mcap convert`) on a session: the protobuf layer turns every
    channel into a struct with the schema's field names; a format-1 file's JSON wrench does not."""
    _rerun()

    def convert(mcap, rrd):
        r = subprocess.run([sys.executable, "-m", "rerun", "mcap", "convert", str(mcap), "-o", str(rrd)],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        return _columns(rrd)

    def struct_fields(cols: dict, schema: str) -> set[str]:
        typ = cols[f"{schema}:message"][0].type  # list<struct<...>>
        return {typ.value_type.field(i).name for i in range(typ.value_type.num_fields)}

    cols = convert(write_full_session(tmp_path / "full.mcap"), tmp_path / "full.rrd")
    assert {"force_n", "torque_nm", "status", "seq", "host_t_ns"} <= struct_fields(cols[S.WRENCH_TOPIC],
                                                                                   "layerskin.Wrench")
    assert {"kind", "message", "detail_json"} <= struct_fields(cols[S.EVENTS_TOPIC], "layerskin.ProtocolEvent")
    assert {"marker_id", "frame_seq", "corners_px"} <= struct_fields(cols[S.marker_detection_topic(0)],
                                                                     "layerskin.MarkerDetection")
    assert "position_mm" in struct_fields(cols[S.STAGE_TOPIC], "layerskin.StagePosition")
    assert "object_detected" in struct_fields(cols[S.GRIPPER_TOPIC], "layerskin.GripperState")
    assert _rows(cols[S.SKIN_TOPICS["superficial"]], "Image:buffer") > 0  # foxglove.RawImage -> Image

    from test_channel_schemas import FORMAT1

    old = convert(FORMAT1, tmp_path / "old.rrd")
    assert not any(name.endswith(":message") and name.startswith("layerskin.") for name in old[S.WRENCH_TOPIC])


# ------------------------------------------------------------------------------ bad input


def test_view_names_a_missing_file_and_a_file_that_is_no_session(tmp_path, capsys):
    assert main(["view", str(tmp_path / "nope.mcap"), "--save", str(tmp_path / "x.rrd")]) == 2
    err = capsys.readouterr().err
    assert "nope.mcap" in err and "no such file" in err
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all" * 10)
    assert main(["view", str(junk), "--save", str(tmp_path / "x.rrd")]) == 2
    err = capsys.readouterr().err
    assert "junk.mcap" in err and "error:" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["view", str(empty)]) == 2
    assert "no .mcap session" in capsys.readouterr().err


def test_view_without_rerun_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    session = write_platform_session(tmp_path / "press.mcap")
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` raises ImportError
    assert main(["view", str(session)]) == 2
    err = capsys.readouterr().err
    assert "rerun-sdk" in err and "pip install 'layerskin-exp[view]'" in err


def test_the_skin_totals_and_cop_plots_come_from_the_stored_summary_channel(tmp_path):
    """/skin/summary is a view channel the reader skips; the viewer reads it for its two plots."""
    _rerun()
    from log_records import frame

    from layerskin_exp.log import SessionWriter
    from layerskin_exp.log.view import SkinView

    path, view, n = tmp_path / "summary.mcap", SkinView(), 0
    with SessionWriter(path) as w:
        for i in range(300):
            f = frame(i)
            w.write(f)
            for topic, schema, payload in view.summary(f):
                w.write_view(topic, schema, payload, f.host_t_ns)
                n += topic == S.SKIN_SUMMARY_TOPIC
    cols = _columns(V.save([path], tmp_path / "summary.rrd")[0])
    for layer in S.SKIN_TOPICS:
        assert _rows(cols[f"{S.SKIN_SUMMARY_TOPIC}/{layer}/total_counts"], "Scalars:scalars") == n > 0
        assert _rows(cols[f"{S.SKIN_SUMMARY_TOPIC}/{layer}/cop_mm"], "Scalars:scalars") == n
