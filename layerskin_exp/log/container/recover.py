"""Rewrite a session whose writer died (no footer), or a damaged one, into a valid, indexed MCAP
marked incomplete, keeping every message that can be read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap.writer import Writer

import layerskin_exp
from layerskin_exp.log.container.scan import SessionFileError, link_loop_error, scan
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session.metacheck import check_records, with_check


def recover(src, dst) -> int:
    """Copy every readable record of `src` into a new MCAP file `dst`. Returns messages copied.

    The outcome stays absent (the trial did not finish, or its file was damaged); a "recovered"
    metadata record names the source, the number of messages saved, the damage found, the
    lost time ranges, the exact repeats dropped per stream (a chunk present twice) and the
    metadata fields left out for failing their check (never copied as if valid). `dst` must not
    exist. Raises SessionFileError for a source with nothing readable, that is not a layerskin
    session, or whose links loop; OSError naming `dst` where it cannot be written (a full disk),
    after removing what was written of it.
    """
    src, dst = Path(src), Path(dst)
    if dst.exists():
        raise FileExistsError(f"{dst} exists; recover into a new file")
    if _resolved(src) == _resolved(dst):
        raise ValueError("recover writes a new file; give an output path different from the input")
    sc = scan(src)
    ours = sc.damaged and any(c.metadata.get("stream") for c in sc.channels.values())
    if not any(name == S.META_SESSION for name, _ in sc.metadata) and not ours:
        raise SessionFileError(f"{src}: not a layerskin session; nothing to recover")
    order = []  # (offset in data, old channel id, index within channel)
    for cid, m in sc.messages.items():
        if m.channel is not None:
            order.append(np.stack([m.offset, np.full(m.count, cid), np.arange(m.count)], axis=1))
    rows = np.concatenate(order) if order else np.zeros((0, 3), np.int64)
    rows = rows[np.argsort(rows[:, 0], kind="stable")]
    payloads = {cid: sc.payloads(m) for cid, m in sc.messages.items() if m.channel is not None}
    try:
        _write(dst, sc, rows, payloads, src)
    except BaseException as exc:
        dst.unlink(missing_ok=True)  # made here (it did not exist): no empty or cut-off output is left
        if isinstance(exc, OSError):
            failed = OSError(f"{dst}: cannot be written ({exc.strerror or exc}); nothing was left there")
            failed.errno = exc.errno
            raise failed from None
        raise
    return len(rows)


def _resolved(path: Path) -> Path:
    try:
        return path.resolve()
    except (RuntimeError, OSError):  # a link loop: RuntimeError before Python 3.13, OSError after
        raise link_loop_error(path) from None


def _write(dst: Path, sc, rows, payloads, src: Path) -> None:
    with open(dst, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library=f"layerskin-exp/{layerskin_exp.__version__} recover")
        kept, damaged_fields, unchecked = check_records(sc.metadata, sc.has_footer)
        for name, values in kept:  # damaged fields left out; those kept vouched for again
            if name not in (S.META_OUTCOME, S.META_RECOVERED):
                w.add_metadata(name, values if name in unchecked else with_check(name, values))
        schema_ids = {}
        for sid, s in sorted(sc.schemas.items()):
            schema_ids[sid] = w.register_schema(s.name, s.encoding, s.data)
        channel_ids = {}
        for cid in sorted(payloads):
            c = sc.channels[cid]
            channel_ids[cid] = w.register_channel(
                c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), c.metadata
            )
        for _off, cid, i in rows.tolist():
            h = sc.messages[cid].header[i]
            w.add_message(
                channel_ids[cid],
                int(h["log_time"]),
                payloads[cid][i],
                int(h["publish_time"]),
                int(h["sequence"]),
            )
        note = "; ".join(sc.warnings) or "file was complete"
        repeats: dict[str, int] = {}
        for cid, k in sc.repeats.items():
            stream = (sc.channels[cid].metadata.get("stream") or sc.channels[cid].topic) if cid in sc.channels else str(cid)
            repeats[stream] = repeats.get(stream, 0) + k
        w.add_metadata(S.META_RECOVERED, with_check(
            S.META_RECOVERED,
            {
                "messages": str(len(rows)),
                "source": S.dumps(str(src)).decode(),
                "damage": S.dumps(note).decode(),
                "lost": S.dumps(
                    [{"start_ns": x.start_ns, "end_ns": x.end_ns, "reason": x.reason} for x in sc.lost]
                ).decode(),
                "repeats": S.dumps(repeats).decode(),
                "damaged_metadata": S.dumps(damaged_fields).decode(),
            },
        ))
        w.finish()
