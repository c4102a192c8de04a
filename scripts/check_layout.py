#!/usr/bin/env python3
"""The project's rooms and the one direction of their includes.

Each room is a folder with one job (README.md "Layout"); a file may include
its own room and the rooms below it, never one above:

    core  <  log  <  io, drivers  <  daemon/device  <  daemon/engine
          <  daemon/scene  <  daemon/service  <  daemon/cli

io/ and drivers/ are siblings (neither includes the other). tests/ and bench/
may include any room. Also checked: every folder of source files belongs to a
room the README's layout table names, and every folder the table names exists.

Usage: check_layout.py [REPO]   (exit 1 with one line per violation)
"""
import pathlib
import re
import sys

# Room -> the rooms it may include (besides itself).
ALLOWED = {
    "core": set(),
    "log": {"core"},
    "io": {"core", "log"},
    "drivers": {"core", "log"},
    "daemon/device": {"core", "log", "drivers"},
    "daemon/engine": {"core", "log", "io", "drivers", "daemon/device"},
    "daemon/scene": {"core", "log", "io", "drivers", "daemon/device", "daemon/engine"},
    "daemon/service": {"core", "log", "io", "drivers", "daemon/device", "daemon/engine", "daemon/scene"},
    "daemon/cli": {"core", "log", "io", "drivers", "daemon/device", "daemon/engine", "daemon/scene",
                   "daemon/service"},
}
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')
SOURCE_SUFFIXES = {".cpp", ".hpp", ".h", ".cc"}


def room_of(path: str):
    """The room a repository path belongs to (the longest room prefix), or None."""
    best = None
    for room in ALLOWED:
        if path == room or path.startswith(room + "/"):
            if best is None or len(room) > len(best):
                best = room
    return best


def readme_folders(readme: pathlib.Path):
    """The folders named in the first column of README.md's layout table."""
    folders, in_table = [], False
    for line in readme.read_text(encoding="utf-8").splitlines():
        if line.startswith("## Layout"):
            in_table = True
            continue
        if in_table and line.startswith("## "):
            break
        if in_table and line.startswith("|") and not line.startswith("|---"):
            first = line.split("|")[1]
            folders += [f.rstrip("/") for f in re.findall(r"`([a-z_./]+/)`", first)]
    return folders


def main() -> int:
    repo = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parent.parent)
    problems = []
    for top in ("core", "log", "io", "drivers", "daemon"):
        for f in sorted((repo / top).rglob("*")):
            if f.suffix not in SOURCE_SUFFIXES or not f.is_file():
                continue
            rel = f.relative_to(repo).as_posix()
            room = room_of(rel)
            if room is None:
                problems.append(f"{rel}: in no room (daemon/ files live in one of its room folders)")
                continue
            for n, line in enumerate(f.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
                m = INCLUDE.match(line)
                if not m or "/" not in m.group(1):
                    continue
                target = room_of(m.group(1))
                if target is None:
                    if not (repo / m.group(1)).exists():
                        problems.append(f"{rel}:{n}: includes \"{m.group(1)}\", which is not in the repository")
                    continue
                if target != room and target not in ALLOWED[room]:
                    problems.append(f"{rel}:{n}: {room} includes \"{m.group(1)}\" of {target}, a room above it or "
                                    f"beside it (allowed: {', '.join(sorted(ALLOWED[room])) or 'nothing'})")
    listed = readme_folders(repo / "README.md")
    for folder in listed:
        if not (repo / folder).is_dir():
            problems.append(f"README.md layout table: {folder}/ does not exist")
    for room in ALLOWED:
        if (repo / room).is_dir() and not any(room == l or room.startswith(l + "/") for l in listed):
            if not any(l.startswith(room + "/") for l in listed):
                problems.append(f"README.md layout table: the room {room}/ is not named")
    if (repo / "daemon").is_dir():
        for sub in sorted(p for p in (repo / "daemon").iterdir() if p.is_dir()):
            rel = sub.relative_to(repo).as_posix()
            if rel not in listed:
                problems.append(f"README.md layout table: {rel}/ is not named")
    for p in problems:
        print(p)
    print(f"check_layout: {len(problems)} problem(s)" if problems else "check_layout: every include goes down; "
          f"the README names all {len(listed)} folders")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
