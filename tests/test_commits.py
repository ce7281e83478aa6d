"""Commit subjects since the house refactor (issue #22): at most 72
characters, in the imperative, capitalised, without a closing full stop; the
why goes in the body. (Earlier history is left as it is: rewriting published
commits would break every clone.)

Runs on a git checkout with that history (a clean clone, as CI makes); an
unpacked sdist or a shallow clone without the baseline commit skips.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The last commit before the rule: "Refuse a model path the system cannot look up with a typed error".
BASELINE = "172ceba"
LIMIT = 72
#: Imperative verbs that happen to end like a past tense or a gerund.
NOT_PAST = {"Embed", "Exceed", "Feed", "Need", "Proceed", "Seed", "Shed", "Speed", "Succeed", "Bring", "String"}


def _subjects() -> list[tuple[str, str]]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    known = subprocess.run(["git", "-C", str(ROOT), "cat-file", "-e", f"{BASELINE}^{{commit}}"],
                           capture_output=True, check=False)
    if known.returncode != 0:
        pytest.skip(f"the baseline commit {BASELINE} is not in this clone's history")
    out = subprocess.run(["git", "-C", str(ROOT), "log", "--format=%h%x09%s", f"{BASELINE}..HEAD"],
                         capture_output=True, text=True, check=True).stdout
    return [(sha, subject) for sha, _, subject in (line.partition("\t") for line in out.splitlines() if line)]


def _problems(subject: str) -> list[str]:
    found = []
    if len(subject) > LIMIT:
        found.append(f"{len(subject)} characters")
    first = subject.split(" ", 1)[0]
    if not first[:1].isupper():
        found.append("not capitalised")
    if first not in NOT_PAST and (first.endswith("ed") or first.endswith("ing")):
        found.append(f"{first!r} is not the imperative")
    if subject.endswith("."):
        found.append("ends with a full stop")
    return found


def test_the_rule_refuses_what_it_should():
    assert _problems("Refuse a step that is not a whole number of samples") == []
    assert _problems("Merge branch 'h1': the H-infinity design in three modules") == []
    assert _problems("Embed the status bridge") == []
    assert _problems("Added a test") == ["'Added' is not the imperative"]
    assert _problems("Fixing the cache") == ["'Fixing' is not the imperative"]
    assert _problems("fix the cache.") == ["not capitalised", "ends with a full stop"]
    assert _problems("A" * 73) == ["73 characters"]


def test_commit_subjects_since_the_refactor_follow_the_rule():
    bad = [f"{sha} {subject!r}: {', '.join(p)}" for sha, subject in _subjects() if (p := _problems(subject))]
    assert bad == []
