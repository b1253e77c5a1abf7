"""The shadow-map pass of pybullet's EGL renderer plugin, switched on or off.

Before every frame the plugin's ``GLInstancingRenderer::renderScene`` draws the whole scene into a large
shadow map and then draws the frame with a shader that samples it: on Mesa's llvmpipe (no GPU) that pass
is two thirds of a frame, about 15 ms at any image size (a 64×48 frame costs as much as 320×240). pybullet
offers no switch for it: its ``shadow=0`` argument and ``configureDebugVisualizer(COV_ENABLE_SHADOWS, 0)``
reach TinyRenderer and the GUI, not the plugin. The pass is chosen by one global ``bool useShadowMap``
in the plugin's own code; :func:`shadow_map_switch` finds that flag through the symbol table of the
plugin's file and the address the plugin was loaded at (``/proc/self/maps``), checks that it holds a
boolean in a writable mapping of that file, and :class:`ShadowMapSwitch` sets it. Anything unexpected
(another platform, a stripped or different build, the plugin not loaded) leaves the plugin untouched and
says why.

Without the pass the plugin draws with its plain shader: the same geometry, colours, textures and
diffuse light, no cast shadows and no specular highlight (TinyRenderer, which rendered every training
image, draws no cast shadows either: ``shadow=0``). The flag is per process and per plugin file: every EGL
client in a process shares it.
"""

from __future__ import annotations

import ctypes
import os
import struct
import sys

__all__ = ["SHADOW_FLAG_SYMBOL", "ShadowMapSwitch", "elf_symbol", "shadow_map_switch"]

#: the plugin's global that selects the shadow-map pass (``examples/OpenGLWindow/GLInstancingRenderer.cpp``)
SHADOW_FLAG_SYMBOL = "useShadowMap"

_SHT_SYMTAB = 2
_STT_OBJECT = 1
_symbols: dict[tuple[str, str], tuple[int, int] | None] = {}


def elf_symbol(path: str, name: str) -> tuple[int, int] | None:
    """``(st_value, st_size)`` of the data object ``name`` in the ``.symtab`` of the 64-bit little-endian
    ELF shared object ``path``; None if the file is not one or does not name it (a stripped build)."""
    key = (os.path.realpath(path), name)
    if key in _symbols:
        return _symbols[key]
    found: tuple[int, int] | None = None
    try:
        with open(key[0], "rb") as f:
            data = f.read()
    except OSError:
        data = b""
    if data[:4] == b"\x7fELF" and data[4:6] == b"\x02\x01" and struct.unpack_from("<H", data, 16)[0] == 3:  # ET_DYN
        (phoff, shoff) = struct.unpack_from("<QQ", data, 0x20)
        phentsize, phnum, shentsize, shnum = struct.unpack_from("<HHHH", data, 0x36)
        loads = [struct.unpack_from("<IIQQ", data, phoff + i * phentsize) for i in range(phnum)]
        if not any(ph[0] == 1 and ph[2] == 0 and ph[3] == 0 for ph in loads):  # PT_LOAD at offset 0, vaddr 0
            shnum = 0  # symbol values would not be offsets from the load address
        sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
        want = name.encode()
        for sh in sections:
            if sh[1] != _SHT_SYMTAB or sh[9] <= 0 or not 0 <= sh[6] < shnum:
                continue
            str_off = sections[sh[6]][4]
            for j in range(sh[5] // sh[9]):
                st_name, st_info, _, _, st_value, st_size = struct.unpack_from("<IBBHQQ", data, sh[4] + j * sh[9])
                if st_info & 0xF != _STT_OBJECT:
                    continue
                end = data.find(b"\0", str_off + st_name)
                if data[str_off + st_name : end] == want:
                    found = (int(st_value), int(st_size))
                    break
            if found:
                break
    _symbols[key] = found
    return found


def _mappings(real_path: str) -> list[tuple[int, int, str, int]]:
    """``(start, end, perms, file offset)`` of this process's mappings of ``real_path``."""
    out = []
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split(maxsplit=5)
            if len(parts) == 6 and parts[5].strip() == real_path:
                lo, hi = (int(v, 16) for v in parts[0].split("-"))
                out.append((lo, hi, parts[1], int(parts[2], 16)))
    return out


class ShadowMapSwitch:
    """The plugin's ``useShadowMap`` byte at a checked address (see :func:`shadow_map_switch`)."""

    def __init__(self, address: int) -> None:
        self._flag = ctypes.c_uint8.from_address(address)

    def set(self, enabled: bool) -> None:
        """Draw (True) or skip (False) the shadow-map pass from the next frame on (every client of the process)."""
        self._flag.value = 1 if enabled else 0

    @property
    def enabled(self) -> bool:
        return bool(self._flag.value)


def shadow_map_switch(plugin_path: str | None) -> tuple[ShadowMapSwitch | None, str]:
    """The shadow-map switch of the EGL plugin loaded in this process from ``plugin_path``, or None and
    why not (the plugin is then left as it is). The address holds while the plugin stays loaded: ask for
    the switch after loading the plugin into a client and use it only while that client is connected (when
    the last client that loaded it disconnects, the plugin is unloaded and a later load may map it
    elsewhere)."""
    if not sys.platform.startswith("linux"):
        return None, "not Linux"
    if not plugin_path:
        return None, "no EGL plugin"
    real = os.path.realpath(plugin_path)
    sym = elf_symbol(real, SHADOW_FLAG_SYMBOL)
    if sym is None or sym[1] != 1:
        return None, f"the plugin names no one-byte {SHADOW_FLAG_SYMBOL}"
    try:
        maps = _mappings(real)
    except OSError as e:
        return None, str(e)
    base = next((lo for lo, _, _, off in maps if off == 0), None)
    if base is None:
        return None, "the plugin is not loaded in this process"
    addr = base + sym[0]
    if not any(lo <= addr < hi and perms.startswith("rw") for lo, hi, perms, _ in maps):
        return None, f"{SHADOW_FLAG_SYMBOL} is not in a writable mapping of the plugin"
    value = ctypes.c_uint8.from_address(addr).value
    if value not in (0, 1):
        return None, f"{SHADOW_FLAG_SYMBOL} holds {value}, not a boolean"
    return ShadowMapSwitch(addr), ""
