"""One tidy-rows report type, rendered as aligned text, CSV and JSON.

Every experiment of ccjax ends in rows of plain values (one dict per row, the same keys in every
row: the "tidy" layout). :class:`Report` keeps those rows with the columns its text view shows;
CSV and JSON carry every key of the rows, the text view the chosen columns, aligned so that no
cell runs into the next.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, field

from ccjax.io.files import csv_text_cell


@dataclass(frozen=True)
class Column:
    """One column of a report's text view.

    Attributes:
        key: the row key shown.
        header: the column heading.
        spec: format spec of a cell value (``".4g"``, ``"+.1%"``); ``None`` values print ``missing``.
        width: cell width (a minimum: a longer cell widens the column to it plus one space);
            ``None`` fits the widest cell or heading (plus ``gap``).
        align: ``"<"`` (text) or ``">"`` (numbers).
        gap: spaces before the column.
        missing: the cell of a ``None`` value.
    """

    key: str
    header: str | None = None
    spec: str = ""
    width: int | None = None
    align: str = "<"
    gap: int = 0
    missing: str = "-"

    def cell(self, row: dict) -> str:
        value = row.get(self.key)
        return self.missing if value is None else format(value, self.spec)

    @property
    def heading(self) -> str:
        return self.key if self.header is None else self.header


@dataclass
class Report:
    """Tidy rows with a text view.

    Attributes:
        rows: one dict per row (same keys in every row).
        columns: the text view's columns (default: every key of the first row).
        metadata: fields written before ``rows`` in the JSON object (e.g. ``{"table": "4.2"}``).
        title: lines printed above the text table.
        footer: lines printed below it.
    """

    rows: list[dict]
    columns: Sequence[Column] = ()
    metadata: dict = field(default_factory=dict)
    title: Sequence[str] = ()
    footer: Sequence[str] = ()

    def _columns(self) -> list[Column]:
        if self.columns:
            return list(self.columns)
        keys = list(self.rows[0]) if self.rows else []
        return [Column(key, gap=0 if i == 0 else 2) for i, key in enumerate(keys)]

    def text(self) -> str:
        """The report as text.

        Returns:
            The aligned text table, between the title and footer lines.
        """
        columns = self._columns()
        cells = [[column.cell(row) for column in columns] for row in self.rows]
        widths = []
        for position, column in enumerate(columns):
            longest = max([len(column.heading), *(len(line[position]) for line in cells)])
            if column.width is not None and longest < column.width:
                widths.append(column.width)
            elif column.width is not None:
                # A fixed width is a minimum: a longer cell widens the column and keeps a space
                # after it, so it never runs into the next column.
                widths.append(longest + 1)
            else:
                widths.append(longest)
        head = "".join(" " * c.gap + format(c.heading, f"{c.align}{w}") for c, w in zip(columns, widths, strict=True))
        body = [
            "".join(" " * c.gap + format(v, f"{c.align}{w}") for c, w, v in zip(columns, widths, line, strict=True))
            for line in cells
        ]
        return "\n".join([*self.title, head.rstrip(), *(line.rstrip() for line in body), *self.footer])

    def to_csv(self) -> str:
        """The rows as CSV.

        Returns:
            Every key of the rows, one line per row, with a header line.
        """
        fieldnames = list(self.rows[0]) if self.rows else [c.key for c in self._columns()]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=fieldnames)
        writer.writeheader()
        # Text cells (paths, labels) that a spreadsheet would read as formulas are neutralised;
        # numbers are written as numbers (a negative number is not text).
        writer.writerows({key: csv_text_cell(value) for key, value in row.items()} for row in self.rows)
        return buffer.getvalue()

    def to_json(self) -> str:
        """The report as JSON.

        Returns:
            A JSON object: the metadata fields, then ``rows``.
        """
        return json.dumps({**self.metadata, "rows": self.rows}, indent=1)
