"""What the laryngoscope's fused kernel (softenv.devices.laryngoscope.fused) compiles to on a CUDA GPU,
found without one; writes ``results/fused_kernel_sm<N>.md`` and ``.json``.

Triton compiles the kernel for the target (default ``sm_90``: H100 and H200) as a first launch with the
arguments of :meth:`~softenv.devices.laryngoscope.fused.LaryngoscopeFused.kernel_arguments` would,
through a driver that only names the target (``warmup``: nothing is launched); ptxas (shipped with
Triton) reports the registers a thread uses and the bytes it spills to local memory, and the disassembly
(cuobjdump, also shipped) shows each loop's instructions: the control period's substep loop and the
solver's iterations inside it. A kernel that compiles here compiles on the GPU; its speed is the GPU
bench's (``softenv bench --device cuda --only gpu-haptic``).

    python scripts/fused_kernel_profile.py [--scene SoftSphereHaptic-v0] [--capability 90]
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import torch
import triton
from triton.backends.compiler import GPUTarget
from triton.backends.nvidia.compiler import get_ptxas
from triton.runtime import driver

from softenv._artifact import write_text
from softenv.bench.timing import code_revision
from softenv.devices.laryngoscope import fused
from softenv.devices.laryngoscope.part import laryngoscope_parts
from softenv.envs import HAPTIC_SCENES
from softenv.envs.config import scene_config
from softenv.envs.world import World

TOOLS = Path(triton.__file__).parent / "backends" / "nvidia" / "bin"
FP64 = re.compile(r"^(?:@!?U?P\w+\s+)?D(?:ADD|MUL|FMA)\b")     # a float64 add, multiply or fma, predicated or not


class CompileOnlyDriver:
    """Triton's driver as far as a compile asks it: the device, its stream and the target a launch on a GPU
    of compute capability ``capability`` compiles for. Nothing is launched (``warmup``), so nothing more."""

    def __init__(self, capability: int) -> None:
        self.target = GPUTarget("cuda", capability, 32)

    def get_current_device(self) -> int:
        return 0

    def get_current_stream(self, device: int | None = None) -> int:
        return 0

    def get_current_target(self) -> GPUTarget:
        return self.target


def compile_kernel(scene: str, capability: int) -> tuple[Any, dict[str, Any]]:
    """The fused kernel of ``scene``'s laryngoscope compiled by Triton for ``sm_<capability>`` through the
    launch's own path (its arguments bound, specialised and compiled as a first launch does, then not
    launched), and the arguments of the control period it was compiled for."""
    driver.set_active(CompileOnlyDriver(capability))      # for this process, which launches nothing
    world = World(scene_config(HAPTIC_SCENES[scene], {}))
    device = fused.LaryngoscopeFused(*laryngoscope_parts(world.scene, world.config), fused.BLOCK)
    command = torch.zeros((4, device.n), dtype=torch.float64)
    arguments = device.kernel_arguments(command, device.n_substeps)
    kernel = fused._control_period.warmup(**arguments, **device.launch_options, grid=(1,))
    return kernel, arguments


def ptxas_report(ptx: str, capability: int, work: Path) -> dict[str, int]:
    """ptxas's registers, stack frame and spill bytes of the kernel's entry function."""
    path = work / "kernel.ptx"
    path.write_text(ptx)
    arch = f"sm_{capability}a" if capability >= 90 else f"sm_{capability}"
    # the ptxas Triton itself compiles with for this target (since Triton 3.8 a newer one from sm_90 up)
    log = subprocess.run([get_ptxas(capability).path, f"-arch={arch}", "-v", "-O3", str(path), "-o", str(work / "kernel.cubin")],
                         capture_output=True, text=True, check=True).stderr
    entry = log.split("Function properties for _control_period")[1]
    numbers = [int(x) for x in re.findall(r"(\d+) (?:bytes stack frame|bytes spill stores|bytes spill loads|registers)",
                                          entry)[:4]]
    return dict(zip(("stack_bytes", "spill_store_bytes", "spill_load_bytes", "registers"), numbers))


def counts(body: list[str]) -> dict[str, int]:
    """A stretch of disassembly's instructions, float64 arithmetic, local-memory accesses and calls."""
    return {"instructions": len(body), "fp64": sum(bool(FP64.match(t.strip())) for t in body),
            "local_loads": sum("LDL" in t for t in body), "local_stores": sum("STL" in t for t in body),
            "calls": sum("CALL" in t for t in body)}


def loops(cubin: bytes, work: Path) -> list[dict[str, Any]]:
    """Each loop of the disassembly (a branch back to an earlier address): its instructions, float64
    arithmetic and local-memory accesses (spills)."""
    path = work / "kernel.cubin"
    path.write_bytes(cubin)
    sass = subprocess.run([str(TOOLS / "cuobjdump"), "-sass", str(path)], capture_output=True, text=True,
                          check=True).stdout
    code = [(int(m.group(1), 16), m.group(2)) for m in re.finditer(r"/\*([0-9a-f]{4,})\*/\s+([^;]*);", sass)]
    found = []
    for address, text in code:
        back = re.search(r"\bBRA (?:\S+, )?0x([0-9a-f]+)", text)
        if back and int(back.group(1), 16) < address:
            body = [t for a, t in code if int(back.group(1), 16) <= a <= address]
            found.append({"start": f"{int(back.group(1), 16):#x}", "end": f"{address:#x}", **counts(body)})
    outer = max(found, key=lambda x: x["instructions"], default=None)
    for x in found:
        inside = outer is not None and int(outer["start"], 16) <= int(x["start"], 16) <= int(x["end"], 16) <= int(outer["end"], 16)
        x["role"] = "substeps" if x is outer else "solver iterations" if inside else "other (a slow path's)"
    found.append({"role": "whole kernel", "start": "", "end": "", **counts([t for _, t in code])})
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="SoftSphereHaptic-v0", choices=sorted(HAPTIC_SCENES))
    parser.add_argument("--capability", type=int, default=90, help="the GPU's compute capability, 90 for sm_90")
    parser.add_argument("--out", type=Path, default=Path("results"))
    args = parser.parse_args()
    kernel, arguments = compile_kernel(args.scene, args.capability)
    work = args.out / f".fused_sm{args.capability}"
    work.mkdir(parents=True, exist_ok=True)
    try:
        resources = ptxas_report(kernel.asm["ptx"], args.capability, work)
        found = loops(kernel.asm["cubin"], work)
    finally:
        for path in work.iterdir():
            path.unlink()
        work.rmdir()
    command = "python scripts/fused_kernel_profile.py " + " ".join(sys.argv[1:])
    warps = kernel.metadata.num_warps
    lines = [f"# The fused laryngoscope kernel on sm_{args.capability}, compiled without a GPU", "",
             f"Made by `{command.strip()}` at {code_revision()} (Triton {triton.__version__}): "
             f"{args.scene}'s kernel, {fused.BLOCK} devices a program over {warps} warps (one thread a device), "
             f"no fused multiply-add.", "",
             f"ptxas: **{resources['registers']} registers** a thread, {resources['stack_bytes']} bytes of stack "
             f"({resources['spill_store_bytes']} bytes of spill stores and {resources['spill_load_bytes']} of spill "
             f"loads in the code), {kernel.metadata.shared} bytes of shared memory.", "",
             "Loops of the disassembly (static counts: a loop's body holds the loops inside it), and the whole kernel:", "",
             "| loop | addresses | instructions | float64 add/mul/fma | local loads | local stores | calls |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {x['role']} | {x['start']}-{x['end']} | {x['instructions']} | {x['fp64']} | "
              f"{x['local_loads']} | {x['local_stores']} | {x['calls']} |".replace("| - |", "| |") for x in found]
    lines += ["", "The substeps' loop holds the solver's; local loads and stores are register spills (and the "
              "argument reduction of sin and cos), calls the slow paths of float64 division and of sin and cos. "
              f"An env-step runs the substeps' loop {arguments['count']} times and the solver's "
              f"{arguments['iterations']} times in each."]
    write_text(args.out / f"fused_kernel_sm{args.capability}.md", "\n".join(lines) + "\n")
    write_text(args.out / f"fused_kernel_sm{args.capability}.json",
               json.dumps({"command": command, "triton": triton.__version__, "scene": args.scene,
                           "block": fused.BLOCK, "num_warps": warps, "shared_bytes": kernel.metadata.shared,
                           **resources, "loops": found}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
