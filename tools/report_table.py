"""Markdown tables of ``endeff eval`` reports side by side (e.g. the dev and test splits).

``python -m tools.report_table dev=docs/eval/mocap_dev.json test=docs/eval/mocap_test.json``
prints, per report, the overall scores, every attribute group (``key=value``, in the order of
the attribute keys) and the per-kind recall, temporal and single-frame estimator side by side,
with the share of labels seen (depth readings near them) and the temporal recall over those
where the report has them.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

METHODS = ('temporal', 'single_frame')


def _cell(score: dict[str, Any] | None) -> str:
    if not score or score.get('recall') is None:
        return '- | - | -'
    err = score.get('mean_error_m')
    err_text = '-' if err is None else f'{100 * err:.1f} cm'
    return f"{score['recall']:.3f} | {err_text} | {score['fpr']:.3f}"


def _seen(entry: dict[str, Any]) -> str:
    """``share seen | temporal recall over the seen labels``, dashes without them."""
    seen = entry.get('labels_seen') or {}
    frac, rec = seen.get('fraction'), (seen.get('recall') or {}).get('temporal')
    return (f"{'-' if frac is None else f'{frac:.3f}'} | "
            f"{'-' if rec is None else f'{rec:.3f}'}")


def rows(report: dict[str, Any]) -> list[tuple[str, int, dict[str, Any]]]:
    """(label, bags, entry) for overall and each attribute group, sorted by attribute."""
    out = [('**overall**', len(report['sequences']),
            {**report['overall'], 'labels_seen': report.get('labels_seen')})]
    groups = [(g, e) for g, e in report.get('groups', {}).items() if 'attribute' in e]
    groups.sort(key=lambda item: (item[1]['attribute'], item[0]))
    out += [(f'`{g}`', len(e['sequences']), e) for g, e in groups]
    return out


def table(name: str, report: dict[str, Any]) -> str:
    header = ('| group | bags | temporal recall | error | FPR | single-frame recall | error '
              '| FPR | labels seen | temporal recall, seen |')
    lines = [f'#### {name}', '', header, '|' + ' --- |' * 10]
    for label, n, entry in rows(report):
        lines.append(f'| {label} | {n} | {_cell(entry.get("temporal"))} | '
                     f'{_cell(entry.get("single_frame"))} | {_seen(entry)} |')
    kinds = report.get('kinds', {})
    if kinds:
        lines += ['', '| kind | temporal recall | error | single-frame recall | error | '
                  'temporal recall, seen |', '| --- | --- | --- | --- | --- | --- |']
        for kind in sorted(kinds.get('temporal', {})):
            cells = []
            for m in METHODS:
                k = kinds.get(m, {}).get(kind) or {}
                rec, err = k.get('recall'), k.get('mean_error_m')
                cells.append('-' if rec is None else f'{rec:.3f}')
                cells.append('-' if err is None else f'{100 * err:.1f} cm')
            seen = (kinds.get('temporal', {}).get(kind) or {}).get('seen_recall')
            cells.append('-' if seen is None else f'{seen:.3f}')
            lines.append(f'| {kind} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m tools.report_table', description=__doc__)
    parser.add_argument('reports', nargs='+', metavar='NAME=REPORT.json')
    args = parser.parse_args(argv)
    for item in args.reports:
        name, _, path = item.partition('=')
        with open(path or name, encoding='utf-8') as fh:
            print(table(name if path else path, json.load(fh)), end='\n\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
