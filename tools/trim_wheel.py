"""Repack a wheel without some of its files, keeping it a valid wheel that pip installs.

    python tools/trim_wheel.py IN.whl OUT_DIR --drop 'pkg/assets/*' --keep 'pkg/assets/needed/*' ...

Rules are shell patterns (``fnmatch``: ``*`` also matches ``/``) on the archive paths (``pkg/sub/file.ext``), applied
in the order given: the last rule that matches a file decides (``--drop`` removes it, ``--keep`` keeps it); a file no
rule matches is kept. The ``*.dist-info/`` files are never removed.

The wheel format (PEP 427 / the binary distribution format spec) lists every file of the archive in
``*.dist-info/RECORD`` as ``path,sha256=<urlsafe-b64 digest, no padding>,size``; pip checks each installed file
against it. The repacked wheel keeps the other files byte for byte (so their RECORD lines stay as they were), drops
the RECORD lines of the removed files, and adds ``*.dist-info/TRIMMED`` (the removed paths and the rules, with its own
RECORD line) so that an installed copy tells that it is trimmed. Name and version are unchanged: the output has the
input's file name, in OUT_DIR (which must not be the input's folder).

Prints one summary line (files and bytes removed, sizes before and after) and exits non-zero on a bad wheel or when a
``--keep`` rule (e.g. a file the caller relies on) matches nothing in the wheel.
"""

from __future__ import annotations

import argparse
import base64
import csv
import fnmatch
import hashlib
import io
import sys
import zipfile
from pathlib import Path


class _Rule(argparse.Action):
    """Appends ``(kind, pattern)`` to one ordered list shared by ``--drop`` and ``--keep``."""

    def __call__(self, parser, namespace, values, option_string=None):
        rules = getattr(namespace, "rules", None) or []
        rules.append((self.dest, values))
        namespace.rules = rules


def record_hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode("ascii")


def is_dropped(path: str, rules: list[tuple[str, str]]) -> bool:
    dropped = False
    for kind, pattern in rules:
        if fnmatch.fnmatchcase(path, pattern):
            dropped = kind == "drop"
    return dropped


def dist_info_dir(names: list[str]) -> str:
    dirs = {name.split("/", 1)[0] for name in names if name.split("/", 1)[0].endswith(".dist-info")}
    if len(dirs) != 1:
        raise SystemExit(f"trim_wheel: expected one *.dist-info folder in the wheel, found {sorted(dirs)}")
    return dirs.pop()


def trim(wheel: Path, out_dir: Path, rules: list[tuple[str, str]]) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / wheel.name
    if out.resolve() == wheel.resolve():
        raise SystemExit("trim_wheel: OUT_DIR must not be the input wheel's folder")
    with zipfile.ZipFile(wheel) as source:
        infos = source.infolist()
        names = [info.filename for info in infos]
        dist_info = dist_info_dir(names)
        record_name = f"{dist_info}/RECORD"
        if record_name not in names:
            raise SystemExit(f"trim_wheel: {wheel.name} has no {record_name}")
        removed = [n for n in names if not n.startswith(f"{dist_info}/") and not n.endswith("/") and is_dropped(n, rules)]
        for kind, pattern in rules:
            if kind == "keep" and not any(fnmatch.fnmatchcase(n, pattern) for n in names):
                raise SystemExit(f"trim_wheel: --keep {pattern!r} matches nothing in {wheel.name}")
        removed_set = set(removed)
        rows = list(csv.reader(io.StringIO(source.read(record_name).decode("utf-8"))))
        trimmed_name = f"{dist_info}/TRIMMED"
        note = "\n".join(
            [f"Trimmed from {wheel.name} by tools/trim_wheel.py: {len(removed)} files removed.", "Rules (last match wins):"]
            + [f"  --{kind} {pattern}" for kind, pattern in rules]
            + ["Removed:"]
            + [f"  {name}" for name in removed]
        ).encode("utf-8") + b"\n"
        kept_rows = [row for row in rows if row and row[0] not in removed_set and row[0] not in (record_name, trimmed_name)]
        kept_rows.append([trimmed_name, record_hash(note), str(len(note))])
        kept_rows.append([record_name, "", ""])
        record = io.StringIO()
        csv.writer(record, lineterminator="\n").writerows(kept_rows)
        removed_bytes = sum(info.file_size for info in infos if info.filename in removed_set)
        with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as target:
            for info in infos:
                if info.filename in removed_set or info.filename in (record_name, trimmed_name):
                    continue
                target.writestr(info, source.read(info.filename), compress_type=info.compress_type)
            target.writestr(zipfile.ZipInfo(trimmed_name, date_time=(2020, 1, 1, 0, 0, 0)), note, compress_type=zipfile.ZIP_DEFLATED)
            target.writestr(zipfile.ZipInfo(record_name, date_time=(2020, 1, 1, 0, 0, 0)), record.getvalue(), compress_type=zipfile.ZIP_DEFLATED)
    print(
        f"trim_wheel: {wheel.name}: removed {len(removed)} files ({removed_bytes / 2**20:.1f} MiB unpacked); "
        f"{wheel.stat().st_size / 2**20:.1f} MiB -> {out.stat().st_size / 2**20:.1f} MiB"
    )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("wheel", type=Path)
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--drop", action=_Rule, metavar="PATTERN", help="remove the files matching PATTERN")
    parser.add_argument("--keep", action=_Rule, metavar="PATTERN", help="keep the files matching PATTERN (overrides earlier --drop)")
    args = parser.parse_args(argv)
    rules = getattr(args, "rules", None) or []
    if not rules:
        parser.error("give at least one --drop rule")
    trim(args.wheel, args.out_dir, rules)
    return 0


if __name__ == "__main__":
    sys.exit(main())
