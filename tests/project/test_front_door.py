"""The README stays a front door: short, its test command the one CI runs, and no page it links
to missing."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()


def test_the_readme_is_at_most_200_lines():
    assert len(README.splitlines()) <= 200


def test_ci_runs_exactly_the_readmes_test_command():
    commands = re.findall(r"```bash\n(python3 -m venv .*?)\n```", README)
    test_command = next(c for c in commands if "[test]" in c)
    assert test_command in (ROOT / ".ci" / "run").read_text().splitlines()


def test_every_file_the_readme_links_to_exists():
    targets = {t.split("#")[0] for t in re.findall(r"\]\(([^)#:]+(?:#[^)]*)?)\)", README)}
    assert [t for t in targets if not (ROOT / t).exists()] == []
