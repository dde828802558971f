"""A check stored with each metadata record, so that a damaged record is named, never read as valid.

The records a session cannot be interpreted without (session, log_time, config, labels,
clock_sync, outcome) sit outside the chunks, where MCAP's only check is the whole data section's
CRC: a flipped bit there says "something is damaged" but not what, and `recover` drops that CRC.
So each field the writer stores has a sibling field CHECK_PREFIX + name holding the CRC32 of
(record name, field name, stored value): a damaged field is named and left out, and the rest of
the record is kept (a damaged check costs its one field, a damaged record name all of them).
A record without any check (a file written before the check existed) is "unchecked".
"""

from __future__ import annotations

import zlib

from layerskin_exp.log.session import schema as S

CHECK_PREFIX = "__crc32:"


def _crc(name: str, key: str, value: str) -> str:
    crc = zlib.crc32(b"\0".join((name.encode(), key.encode(), value.encode())))
    return f"{crc:08x}"


def with_check(name: str, values: dict[str, str]) -> dict[str, str]:
    """values (field -> stored string) with, for each field, the check that vouches for it."""
    return {**values, **{CHECK_PREFIX + k: _crc(name, k, v) for k, v in values.items()}}


def verify(name: str, values: dict[str, str]) -> tuple[dict[str, str], list[str], bool]:
    """(the fields that pass their check, the names of those that do not, whether the record
    carries checks). In a checked record a field without its check, or a check without its
    field, is damaged."""
    checks = {k[len(CHECK_PREFIX):]: v for k, v in values.items() if k.startswith(CHECK_PREFIX)}
    fields = {k: v for k, v in values.items() if not k.startswith(CHECK_PREFIX)}
    if not checks:
        return fields, [], False
    good = {k: v for k, v in fields.items() if checks.get(k) == _crc(name, k, v)}
    return good, sorted((set(fields) | set(checks)) - set(good)), True


def check_records(metadata: list[tuple[str, dict[str, str]]], has_footer: bool
                  ) -> tuple[list[tuple[str, dict[str, str]]], list[str], list[str]]:
    """(the records with their damaged fields left out, in file order; the damaged fields as
    "record.field", and "record" for a record the writer wrote but the file lacks; the records
    stored without a check). The Foxglove layout records carry none and are not listed."""
    kept, damaged, unchecked, checked = [], [], [], False
    for name, values in metadata:
        good, bad, has_check = verify(name, values)
        kept.append((name, good))
        damaged += [f"{name}.{k}" for k in bad]
        checked |= has_check
        if not has_check and name not in (S.META_LAYOUT, S.META_LAYOUT_APP) and name not in unchecked:
            unchecked.append(name)
    if checked:  # a writer that checks its records also wrote these ones
        names = {name for name, _ in metadata}
        needed = [S.META_SESSION, S.META_LOG_TIME, S.META_LABELS]
        if has_footer and S.META_RECOVERED not in names:
            needed += [S.META_CLOCK_SYNC, S.META_OUTCOME]
        damaged += [name for name in needed if name not in names]
    return kept, damaged, unchecked
