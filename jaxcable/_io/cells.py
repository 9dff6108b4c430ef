"""The cells of a raw export's rows told apart: numbers, and the text cells of a
status or label column (`Dy_auto`, `OK`) that a data row may carry."""

import re
from collections import Counter

from .parsing import parse_number


NON_NUMBER_WORD = re.compile(r"[^\W\d_]", re.UNICODE)  # any letter


def is_number(cell: str, decimal_comma: bool) -> bool:
    try:
        parse_number(cell, decimal_comma)
    except ValueError:
        return False
    return True


def text_cells(cells: list[str], decimal_comma: bool) -> frozenset[int] | None:
    """The positions of the text cells (`Dy_auto`, `OK`: a letter, not a number) of
    a row of at least 2 numbers, or None if the row is not one or has a cell that
    is neither (empty, `12..5`)."""
    numbers, text = 0, []
    for position, cell in enumerate(cells):
        if is_number(cell, decimal_comma):
            numbers += 1
        elif NON_NUMBER_WORD.search(cell):
            text.append(position)
        else:
            return None
    return frozenset(text) if numbers >= 2 else None


def text_columns_of(rows: list[list[str]], decimal_comma: bool) -> frozenset[int]:
    """The positions of the text columns of the data rows among `rows` (a status or
    label column: RheoCompass writes `Dy_auto` in every row): those of the text
    cells that most rows of at least 2 numbers have (none where most have none).

    A row whose numeric cells are numbers and whose only other cells sit in these
    columns is a data row; the columns are then not read, but for the header
    naming one as a quantity, whose cells are then reported as not numbers.
    """
    shapes = Counter(
        shape
        for shape in (text_cells(cells, decimal_comma) for cells in rows)
        if shape is not None
    )
    if not shapes:
        return frozenset()
    # Of as common ones, the one with fewer text columns.
    return max(shapes, key=lambda shape: (shapes[shape], -len(shape)))
