"""Checks of the CLI contract, for tests: bad input gives one clear line and a non-zero exit."""


def one_line_error(result) -> str:
    """The single error line of a failed `CliRunner` result; fails if there is a traceback or more."""
    assert result.exit_code != 0, f"expected failure, got exit 0:\n{result.output}"
    assert "Traceback" not in result.output, result.output
    lines = [line for line in result.output.strip().splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    return lines[0]
