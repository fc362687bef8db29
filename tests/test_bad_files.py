"""The corpus of bad inputs (tests/bad_inputs.py): every reader refuses each damaged file with
an EventFileError that names the file and says what is wrong; never another exception."""

from __future__ import annotations

from pathlib import Path

import bad_inputs
import pecs
import pecs.io
import pytest

CASES = bad_inputs.bad_cases()


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return bad_inputs.valid_files(tmp_path_factory.mktemp("seeds"))


@pytest.mark.parametrize("case", [pytest.param(case, id=case.name) for case in CASES])
def test_bad_input_raises_event_file_error_naming_file(seeds, tmp_path, case):
    path = tmp_path / f"bad{case.suffix}"
    path.write_bytes(case.make(seeds))
    if case.fragment is None:
        assert pecs.io.read_events(path, format=case.format).num_rows == 0
        return
    with pytest.raises(pecs.io.EventFileError) as caught:
        pecs.io.read_events(path, format=case.format)
    assert caught.value.path == path
    assert str(caught.value).startswith(str(path))
    assert case.fragment in str(caught.value)


@pytest.mark.parametrize("seed", sorted(bad_inputs.LOOKS_LIKE))
def test_misnamed_file_says_what_it_looks_like(seeds, tmp_path, seed):
    """A file read under another format's suffix is named for what it is."""
    target = ".txt" if seed != "text" else ".h5"
    path = tmp_path / f"misnamed{target}"
    path.write_bytes(seeds[seed].read_bytes())
    with pytest.raises(pecs.io.EventFileError, match="looks like " + bad_inputs.LOOKS_LIKE[seed]):
        pecs.io.read_events(path)


def test_every_seed_reads_back_its_events(seeds):
    """The seeds themselves are valid: the corpus damages files that do read."""
    want = bad_inputs.small_events()
    for name, path in seeds.items():
        back = pecs.io.read_events(path, format=bad_inputs.SEEDS[name][1])
        for column in ("t", "x", "y", "p"):
            assert back.column(column).to_pylist() == want.column(column).to_pylist(), name
