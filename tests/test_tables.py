"""Chapter tables: numbers with intervals, Markdown tables, the paper's table beside ours; the paper's
printed numbers."""
import numpy as np
import pytest

from facelib import paper, tables


def test_a_value_carries_its_interval_with_the_digits_asked():
    assert tables.interval_cell(83.04, (75.0, 90.46)) == "83 [75, 90]"
    assert tables.interval_cell(1.234, (0.5, 2.0), digits=1) == "1.2 [0.5, 2.0]"
    assert tables.interval_cell(7.0) == "7"


def test_a_rate_cell_is_the_mean_in_percent_inside_its_bootstrap_interval():
    cell = tables.rate_cell(np.arange(40) % 4 == 0)  # 25 %
    value, low, high = (float(v) for v in cell.replace("[", "").replace("]", "").replace(",", "").split())
    assert value == 25 and 0 <= low < 25 < high <= 100


def test_markdown_table_has_a_header_a_rule_and_a_line_per_row_and_refuses_ragged_rows():
    text = tables.markdown(["a", "b"], [[1, "x"], [2, "y"]])
    assert text.splitlines() == ["| a | b |", "|---|---|", "| 1 | x |", "| 2 | y |"]
    with pytest.raises(ValueError, match="every row needs 2 cells"):
        tables.markdown(["a", "b"], [[1]])


def test_ranks_order_by_the_better_direction():
    assert tables.ranks([3.0, 9.0, 5.0]) == [3, 1, 2]
    assert tables.ranks([3.0, 9.0, 5.0], higher_is_better=False) == [1, 3, 2]


def test_paper_beside_ours_says_where_the_ordering_holds_and_where_our_intervals_cannot_tell():
    printed = {"GT": 86.0, "baseline": 80.7, "ours": 82.0}
    same = tables.paper_beside_ours(printed, {"GT": (88, (84, 91)), "baseline": (19, (15, 23)),
                                              "ours": (83, (80, 87))})
    assert [r[-1] for r in same] == ["yes", "yes", "yes"] and same[0][3] == "1 / 1"
    swapped = tables.paper_beside_ours(printed, {"GT": (80, (76, 84)), "baseline": (50, (45, 55)),
                                                 "ours": (83, (80, 87))})
    assert [r[-1] for r in swapped] == ["no (intervals overlap)", "yes", "no (intervals overlap)"]
    # a swap is judged against the method it swapped with: A > B > C > D printed, B > C > D > A here
    four = tables.paper_beside_ours({"A": 4.0, "B": 3.0, "C": 2.0, "D": 1.0},
                                    {"A": (1, (0, 2)), "B": (9, (8, 10)), "C": (7, (6, 8.5)), "D": (5, (4, 6))})
    assert [r[-1] for r in four] == ["**no**", "**no**", "**no**", "**no**"]
    close = tables.paper_beside_ours({"A": 4.0, "B": 3.0, "C": 2.0},
                                     {"A": (5, (4, 7)), "B": (6, (5, 8)), "C": (1, (0, 2))})
    assert [r[-1] for r in close] == ["no (intervals overlap)", "no (intervals overlap)", "yes"]
    apart = tables.paper_beside_ours(printed, {"GT": (60, (55, 65)), "baseline": (50, (45, 55)),
                                               "ours": (83, (80, 87))})
    assert apart[0][-1] == "**no**"
    with pytest.raises(ValueError, match="not in the paper's table"):
        tables.paper_beside_ours(printed, {"GT": (1, None), "other": (2, None)})
    partial = tables.paper_beside_ours(printed, {"GT": (88, (84, 91)), "ours": (83, (80, 87))})
    assert partial[1][2:] == ["not reproduced", "", ""] and partial[2][3:] == ["2 / 2", "yes"]
    assert partial[0][1] == "86.00"  # the paper's value as printed, two decimals


def test_the_paper_tables_have_every_column_for_every_method():
    for name in ("Acc (rtt)", "FID (rtt)", "Acc (ent)", "FID (ent)"):
        assert set(paper.column(paper.TABLE_2, name)) == {"ground truth", "MotionCLIP", "ours (Alg. 2)"}
    assert paper.column(paper.TABLE_2, "Acc (rtt)")["ours (Alg. 2)"] == 82.01
    with pytest.raises(ValueError, match="no column 'Acc'"):
        paper.column(paper.TABLE_2, "Acc")


def test_every_paper_table_has_the_same_columns_for_each_method():
    for table in (paper.TABLE_1, paper.TABLE_2, paper.TABLE_3, paper.TABLE_4, paper.TABLE_5):
        columns = {frozenset(row) for row in table.values()}
        assert len(columns) == 1, table
    # the printed orderings the chapters compare with: ours first in Tables 1 and 5, GT first in Table 2
    assert max(paper.TABLE_1, key=lambda m: paper.TABLE_1[m]["Acc (CoMA)"]) == "ours"
    assert min(paper.TABLE_5, key=lambda m: paper.TABLE_5[m]["identity split"][0]) == "ours"


def test_paper_and_ours_stacks_columns_with_their_direction():
    ours = {"Acc (rtt)": {m: (v, None) for m, v in paper.column(paper.TABLE_2, "Acc (rtt)").items()},
            "FID (rtt)": {m: (v, None) for m, v in paper.column(paper.TABLE_2, "FID (rtt)").items()}}
    rows = tables.paper_and_ours(paper.TABLE_2, ours, lower_is_better=("FID (rtt)",))
    assert len(rows) == 6 and all(r[-1] == "yes" for r in rows)
    assert [r[4] for r in rows if r[0] == "FID (rtt)"] == ["1 / 1", "3 / 3", "2 / 2"]
