"""How the white-image rule (:func:`lfrefract.formats.whites.white_problem`) reads Lytro files.

For each Lytro file given (``.raw`` with its metadata, ``.lfr``): the measures the rule judges by
(:func:`lfrefract.formats.whites.white_measures`: saturated share, gap share, even share) and its
verdict. Give it a run's white images and captures (``lfsim experiment pipeline --renders DIR`` keeps
them: ``DIR/renders/whites/*/white_000.raw``, ``DIR/renders/real/*/left/capture.lfr``); a white must
pass, a capture must not. The lines are sorted by the even share.

    python benchmarks/measure_white_rule.py RUN/renders/whites/left/white_000.raw RUN/renders/real/*/left/capture.lfr
"""

from __future__ import annotations

import argparse
import time

from lfrefract.formats.whites import (
    WHITE_EVEN_SHARE,
    WHITE_RING_FRACTION,
    flat_field,
    read_lytro_file,
    white_measures,
    white_problem,
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+", help="Lytro files (.raw with metadata, .lfr)")
    args = parser.parse_args(argv)
    rows = []
    for path in args.files:
        capture = read_lytro_file(path)
        field = flat_field(capture.mosaic)
        pitch = capture.camera.micro_image_pitch_px
        start = time.perf_counter()
        measures = white_measures(capture.mosaic, field, micro_image_pitch_px=pitch)
        seconds = time.perf_counter() - start
        problem = white_problem(capture.mosaic, field, micro_image_pitch_px=pitch)
        verdict = "white" if problem is None else "refused: " + problem.split(":")[0]
        rows.append((measures.even_share, path, capture.mosaic.shape, measures, seconds, verdict))
    print(
        f"rule: a white's micro-images reach {WHITE_RING_FRACTION:g} of their ring's level in at least "
        f"{100 * WHITE_EVEN_SHARE:.0f} % of its lit field"
    )
    print("| file | pixels | saturated % | gaps % | even % | measured s | verdict |")
    print("|---|---|---|---|---|---|---|")
    for even, path, shape, measures, seconds, verdict in sorted(rows, key=lambda row: row[0]):
        print(
            f"| {path} | {shape[1]} x {shape[0]} | {100 * measures.saturated_share:.2f} | "
            f"{100 * measures.gap_share:.0f} | {100 * even:.0f} | {seconds:.2f} | {verdict} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
