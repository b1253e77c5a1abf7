"""One glibc malloc arena per OCSLAM process (app/memory.py), unless the user's MALLOC_ARENA_MAX says otherwise."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc arenas")

# threads that allocate at once, then glibc's own report of its arenas (malloc_info: one <heap> each)
_CODE = textwrap.dedent("""
    import ctypes, json, os, tempfile, threading
    import app  # noqa: F401  (sets the arena limit on import)
    libc = ctypes.CDLL(None)
    if getattr(libc, "gnu_get_libc_version", None) is None:
        print(json.dumps({"glibc": False})); raise SystemExit
    libc.malloc.restype = ctypes.c_void_p
    libc.free.argtypes = [ctypes.c_void_p]
    start = threading.Barrier(6)
    def work():
        start.wait()
        blocks = [libc.malloc(4096) for _ in range(2000)]
        start.wait()
        for b in blocks: libc.free(b)
    ts = [threading.Thread(target=work) for _ in range(6)]
    [t.start() for t in ts]; [t.join() for t in ts]
    path = tempfile.mktemp()
    libc.fopen.restype = ctypes.c_void_p
    libc.fopen.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
    libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
    libc.fclose.argtypes = [ctypes.c_void_p]
    fp = libc.fopen(path.encode(), b"w"); libc.malloc_info(0, fp); libc.fclose(fp)
    xml = open(path).read(); os.unlink(path)
    print(json.dumps({"glibc": True, "arenas": xml.count("<heap nr=")}))
""")


def _arenas(env_extra: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"} | env_extra
    out = subprocess.run([sys.executable, "-c", _CODE], capture_output=True, text=True, timeout=120, check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_threads_share_one_arena():
    r = _arenas({})
    if not r["glibc"]:
        pytest.skip("not glibc")
    assert r["arenas"] == 1


def test_the_users_malloc_arena_max_wins():
    r = _arenas({"MALLOC_ARENA_MAX": "4"})
    if not r["glibc"]:
        pytest.skip("not glibc")
    assert r["arenas"] > 1
