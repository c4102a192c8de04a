#!/usr/bin/env python3
"""Keeps each test file's names in a namespace of its own.

The room test executables compile as unity batches (tests/CMakeLists.txt:
eight test files to a translation unit, issue 25), so two files' file-local
helpers with one name would meet. Each tests/<room>/test_*.cpp therefore
opens `namespace unity_<room>_<file> {` right after its top #include block and
closes it at its end; the project's namespaces the file reopens are reopened
inside it with a using-directive, so `namespace imuemu { ... }` in a test still
sees the library's names.

  scripts/test_namespace.py --check   lists the files that lack it (exit 1)
  scripts/test_namespace.py --write   adds it to them

The files CMake keeps out of the batches (SKIP_UNITY_BUILD_INCLUSION in
tests/CMakeLists.txt: a replaced global operator new, a #define, an include
after code) need no namespace and are left alone.
"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
# Rooms whose files are not in the unity batches (their own executables).
OWN_EXECUTABLE_ROOMS = ('memory', 'support', 'loopback', 'fuzz')
COMMENT = "// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt)."


def stand_alone_files():
    """Files tests/CMakeLists.txt keeps out of the unity batches."""
    cmake = (ROOT / 'tests' / 'CMakeLists.txt').read_text()
    return set(re.findall(r'\$\{CMAKE_CURRENT_SOURCE_DIR\}/(\S+\.cpp) PROPERTIES SKIP_UNITY_BUILD_INCLUSION', cmake))


def wrapped(text, name):
    return f'namespace {name} {{' in text and f'}}  // namespace {name}' in text


def wrap(lines, name):
    """The file with its body (after the top #include block) in namespace NAME."""
    includes = [i for i, line in enumerate(lines) if line.startswith('#include')]
    first_body_line = includes[-1] + 1
    while first_body_line < len(lines) and lines[first_body_line].startswith('#') \
            and not lines[first_body_line].startswith('#define'):
        first_body_line += 1
    body = lines[first_body_line:]
    while body and body[-1] == '':
        body.pop()
    reopened = ['imuemu']
    for line in body:
        match = re.match(r'^namespace (imuemu(::\w+)+) \{', line)
        if match and match.group(1) not in reopened:
            reopened.append(match.group(1))
    opener = ['', COMMENT]
    opener += [f'namespace {ns} {{}}' for ns in reopened]
    opener.append(f'namespace {name} {{')
    opener += [f'namespace {ns} {{ using namespace ::{ns}; }}' for ns in reopened]
    return lines[:first_body_line] + opener + body + [f'}}  // namespace {name}', '']


def main():
    if len(sys.argv) != 2 or sys.argv[1] not in ('--check', '--write'):
        print(__doc__)
        return 2
    stand_alone = stand_alone_files()
    missing = []
    for path in sorted(ROOT.glob('tests/*/test_*.cpp')):
        room = path.parent.name
        relative = f'{room}/{path.name}'
        if room in OWN_EXECUTABLE_ROOMS or relative in stand_alone:
            continue
        name = f'unity_{room}_{path.stem}'
        text = path.read_text()
        if wrapped(text, name):
            continue
        missing.append(f'tests/{relative}')
        if sys.argv[1] == '--write':
            path.write_text('\n'.join(wrap(text.split('\n'), name)))
    if missing and sys.argv[1] == '--check':
        print('test files without their own namespace (run scripts/test_namespace.py --write,')
        print('or list the file in tests/CMakeLists.txt with SKIP_UNITY_BUILD_INCLUSION):')
        print('\n'.join('  ' + m for m in missing))
        return 1
    for m in missing:
        print('wrapped', m)
    return 0


if __name__ == '__main__':
    sys.exit(main())
