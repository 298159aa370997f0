"""InputError names the file and line so that a one-line message is enough to fix the input."""

from worker.errors import InputError


def test_message_names_file_and_line():
    err = InputError("expected 8 numbers, got 3", path="rel.txt", line=17)
    assert str(err) == "rel.txt:17: expected 8 numbers, got 3"
    assert (err.path, err.line) == ("rel.txt", 17)


def test_message_without_location_is_the_bare_message():
    assert str(InputError("resolution must be in (0.005, 1] m")) == (
        "resolution must be in (0.005, 1] m"
    )


def test_is_a_value_error():
    assert isinstance(InputError("x", path="f"), ValueError)
