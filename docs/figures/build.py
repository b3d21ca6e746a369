"""The documentation's figures, made during the docs build: mkdocs-gen-files runs this file (mkdocs.yml,
`gen-files: scripts`); every picture comes from a script here, never a hand-drawn image.

Each figure module in this folder (every `*.py` but this one and the `_` helpers) has
`make(out_dir) -> list[Path]`; each file it writes is published at `figures/<file name>`, where the pages link
to it (`../figures/mission.png` from `tutorials/x.md`). The modules are loaded by path (docs/ is no package),
under names of their own, and without writing `__pycache__` into docs/, which mkdocs would publish.

Preview without mkdocs: `python docs/figures/build.py OUTDIR`.
"""

from __future__ import annotations

import importlib.util
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from types import ModuleType

HERE = Path(__file__).resolve().parent
SITE_FOLDER = "figures"
MODULE_PREFIX = "preland_docs_figures_"  # not `mission` or `report`: those could be someone else's module


def figure_modules(names: Iterable[str] | None = None) -> list[ModuleType]:
    """The figure modules here (or those `names`, file stems), loaded, in name order."""
    paths = sorted(p for p in HERE.glob("*.py") if p.name != "build.py" and not p.name.startswith("_"))
    if names is not None:
        wanted = set(names)
        unknown = wanted - {p.stem for p in paths}
        if unknown:
            raise ValueError(f"no figure module {', '.join(sorted(unknown))} in {HERE}")
        paths = [p for p in paths if p.stem in wanted]
    writes_bytecode = sys.dont_write_bytecode
    sys.dont_write_bytecode = True
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))  # for `import _figkit` in each module
    try:
        modules = []
        for path in paths:
            name = MODULE_PREFIX + path.stem
            if name not in sys.modules:
                spec = importlib.util.spec_from_file_location(name, path)
                module = importlib.util.module_from_spec(spec)
                sys.modules[name] = module  # dataclasses look their module up while it loads
                try:
                    spec.loader.exec_module(module)
                except BaseException:
                    del sys.modules[name]
                    raise
            modules.append(sys.modules[name])
        return modules
    finally:
        sys.dont_write_bytecode = writes_bytecode


def publish(open_file: Callable, modules: Iterable[ModuleType] | None = None, *,
            log: Callable[[str], None] = lambda line: None) -> list[str]:
    """Make every figure into a temporary folder and copy each into the site with
    `open_file("figures/NAME.png", "wb")` (mkdocs_gen_files.open in a build). Returns the site paths."""
    published: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="preland-figures-") as folder:
        for module in (figure_modules() if modules is None else modules):
            started = time.perf_counter()
            out_dir = Path(folder) / module.__name__
            for path in module.make(out_dir):
                site_path = f"{SITE_FOLDER}/{path.name}"
                if site_path in published:  # two modules must not overwrite each other's figure
                    raise ValueError(f"{site_path}: written by {published[site_path]} and {module.__name__}")
                published[site_path] = module.__name__
                with open_file(site_path, "wb") as out:
                    out.write(path.read_bytes())
            log(f"{module.__name__.removeprefix(MODULE_PREFIX)}: {time.perf_counter() - started:.1f} s")
    return list(published)


if __name__ == "<run_path>":  # the name runpy gives a script: mkdocs-gen-files in a docs build
    import logging

    import mkdocs_gen_files

    publish(mkdocs_gen_files.open, log=logging.getLogger("mkdocs.plugins.preland.figures").info)
elif __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(f"usage: python {sys.argv[0]} OUTDIR")
    target = Path(sys.argv[1])

    def write(site_path: str, mode: str):
        (target / site_path).parent.mkdir(parents=True, exist_ok=True)
        return open(target / site_path, mode)

    for site_path in publish(write, log=print):
        print(target / site_path)
