"""Tools beside the planner: fclib (solve an FCLib problem), generate (seeded random fixtures), schema."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from fixplan.cli._app import (
    JsonOpt,
    _emit_json,
    _writable,
    app,
)
from fixplan.errors import InputError
from fixplan.files import write_output, write_text
from fixplan.settings import DEFAULT


def _count(n: int, noun: str) -> str:
    """``1 contact``, ``3 contacts``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


@app.command()
def fclib(
    file: Annotated[Path, typer.Argument(help="An FCLib HDF5 problem (local or global, 3D or 2D).")],
    tol: Annotated[
        float, typer.Option("--tol", help="Target FCLib residual (natural map, relative).")
    ] = DEFAULT.engine.fclib_tolerance,
    max_iter: Annotated[
        int | None,
        typer.Option(
            "--max-iter",
            help="Iteration cap (sweeps for nsgs, rounds for socp/prox, steps for nsn; for auto: of every stage).",
            min=1,
        ),
    ] = None,
    time_limit: Annotated[
        float,
        typer.Option(
            "--time-limit",
            help="Seconds for reading and solving; at the limit the best answer so far is printed (exit 1).",
        ),
    ] = 60.0,
    solver: Annotated[str, typer.Option("--solver", help="auto, nsgs, socp, nsn, prox or nsgs-numpy.")] = "auto",
    json_out: JsonOpt = False,
) -> None:
    """Solve an FCLib frictional-contact problem; exit 0 converged, 1 not converged, 2 bad input.

    auto runs NSGS, then the SOCP fixed point, nonsmooth Newton and PROX, each when the one before
    stalls, and answers with the best reaction found, always within --time-limit.
    """
    from fixplan.engine.fclib import solve_fclib_file

    if not (tol > 0 and np.isfinite(tol)):
        raise InputError(f"--tol must be a positive number, got {tol}")
    if not time_limit > 0:
        raise InputError(f"--time-limit must be a positive number of seconds, got {time_limit}")
    result = solve_fclib_file(file, tol=tol, max_iter=max_iter, solver=solver, time_limit=time_limit)
    if json_out:
        _emit_json({"file": str(file), **result.to_json()}, compact=True)
    else:
        verdict = "converged" if result.converged else "NOT converged"
        typer.echo(
            f"{file}: {result.kind} problem, {_count(result.n_contacts, 'contact')}; {result.solver}: error "
            f"{result.error:.3g} after {_count(result.iterations, 'iteration')} in {result.time_s * 1e3:.1f} ms "
            f"({verdict}, tol {tol:g})"
        )
        for stage in result.stages:
            typer.echo(
                f"  {stage['method']}: {stage['start_error']:.3g} -> {stage['error']:.3g} in "
                f"{_count(stage['iterations'], 'iteration')}, {stage['time_s'] * 1e3:.1f} ms ({stage['status']})"
            )
        if not result.converged:
            typer.echo(f"  best answer kept: {result.extras.get('reason', '')}")
    if not result.converged:
        raise typer.Exit(1)


@app.command()
def generate(
    family: Annotated[str | None, typer.Argument(help="Fixture family (see --list).", show_default=False)] = None,
    count: Annotated[
        int, typer.Option("--count", help="How many fixtures (index 0 .. N-1), at most 10000.", min=1, max=10000)
    ] = 10,
    seed: Annotated[
        int, typer.Option("--seed", help="Seed ≥ 0; fixture k of a seed is the same whatever --count.", min=0)
    ] = 0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Directory for FAMILY-sSEED-NNN.toml (created if absent).")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite existing files.")] = False,
    rotate_world: Annotated[
        bool,
        typer.Option(
            "--rotate-world",
            help="Turn each fixture rigidly (locators, start, goal, gravity) by a seeded random rotation "
            "(uniform on SO(3); a uniform angle in 2D); files are named FAMILY-sSEED-NNN-rotated.toml.",
        ),
    ] = False,
    floor: Annotated[
        bool,
        typer.Option(
            "--floor",
            help="Add a collision-only floor ([[obstacle]] plane normal to gravity) 10 mm below the part's "
            "lowest point at its start and goal; the layouts and draws are those without it.",
        ),
    ] = False,
    list_: Annotated[bool, typer.Option("--list", help="List the families and exit.")] = False,
    json_out: JsonOpt = False,
) -> None:
    """Write seeded random fixtures of a family, each checked before it is written.

    Families: box-321 and plate-2d start resting on the base locators; box-321-free and
    plate-2d-free start in free space (the nearest locator 5-80 mm away, tilted up to 15 deg about
    every axis, mirrored layouts, the goal written in half the files); mesh-321 writes CAD-like mesh
    parts (L-brackets, slotted blocks, housings), each fixture beside its STL file, with a locator
    inside the part's concave region; plane-2-pins loads a box onto a round and a diamond pin, and
    plane-2-pins-mesh the same draws with the box written as a mesh part (STL beside it);
    plane-pin-stop loads a plate onto one round pin against a stop that takes the turn about it,
    from starts tilted up to 10 deg about every axis; shaft-bore loads a shaft, tilted above it,
    into a blind bore (chamfered or sharp). --list describes them.
    """
    from fixplan.generate import ALL_FAMILIES, MESH_FILE_FAMILIES, check_family, fixture_name
    from fixplan.generate import generate as run

    if list_:
        if json_out:
            _emit_json({"families": ALL_FAMILIES})
        else:
            for name, description in ALL_FAMILIES.items():
                typer.echo(f"{name}: {description}")
        return
    if family is None:
        raise InputError("give a FAMILY (one of: " + ", ".join(ALL_FAMILIES) + ") or --list")
    check_family(family)
    if out is None:
        raise InputError("--out DIR is required (the directory to write the fixtures into)")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file (expected a directory)")
    names = [fixture_name(family, seed, i, rotate_world=rotate_world) for i in range(count)]
    targets = [out / f"{name}.toml" for name in names]
    meshes = [out / f"{name}.stl" for name in names] if family in MESH_FILE_FAMILIES else []
    for target in targets + meshes:
        _writable(target, force)
    fixtures = run(family, count, seed, rotate_world=rotate_world, floor=floor)
    for target, fx in zip(targets, fixtures, strict=True):
        for file_name, data in fx.files:  # the mesh first: a fixture is never written without its file

            def write_file(path: Path, data: bytes = data) -> None:
                path.write_bytes(data)

            write_output(out / file_name, write_file)
        write_text(target, fx.toml_text)
    if json_out:
        files = [
            {
                "name": fx.name,
                "path": str(t),
                "params": fx.params,
                **({"files": [str(out / n) for n, _ in fx.files]} if fx.files else {}),
            }
            for t, fx in zip(targets, fixtures, strict=True)
        ]
        _emit_json({"family": family, "seed": seed, "count": count, "out": str(out), "files": files})
    else:
        where = " in rotated worlds" if rotate_world else ""
        with_meshes = " with their STL meshes" if meshes else ""
        typer.echo(
            f"wrote {count} {family} fixtures{with_meshes} (seed {seed}){where} to {out}: "
            f"{targets[0].name} .. {targets[-1].name}"
        )


@app.command()
def schema(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the schema to this file (docs/fixture.schema.json is the shipped copy)."),
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing file.")] = False,
) -> None:
    """Print the JSON Schema of fixture files (draft-07), for TOML editors (Taplo, Even Better TOML) and tools.

    Every key with its type, unit, range, default and description, as fixplan validate reads it;
    checks of the whole fixture (a locator inside the part, goal finding) are validate's alone.
    """
    from fixplan.fixture_schema import schema_text

    text = schema_text()
    if out is None:
        typer.echo(text, nl=False)
        return
    _writable(out, force)
    write_text(out, text)
    typer.echo(f"wrote {out}")
