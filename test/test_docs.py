"""The README and docs/: the two commands, the README's length, every relative link resolves.

The README is a newcomer's page: it stays short, keeps the two commands (set up and run the main
job; set up and run the test suite, which `.ci/run` runs verbatim) and links every page of
docs/. Every relative link of README.md and docs/*.md must name a file that exists and, with an
anchor, a heading of that file (GitHub's anchors: the heading's text, lower case, punctuation
dropped, spaces as hyphens).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
README = REPO / 'README.md'
DOCS = REPO / 'docs'
#: The README's longest length [lines]: a page read in five minutes, the reference in docs/.
MAX_README_LINES = 250
MAIN_JOB_COMMAND = 'sh tools/venv.sh && .venv/bin/python -m gait_nodes run --duration 40 --record'
TEST_COMMAND = 'sh tools/venv.sh && .venv/bin/python -m pytest -q -n auto --dist loadgroup test'

FENCE = re.compile(r'^\s*(```|~~~)')
HEADING = re.compile(r'^(#{1,6})\s+(.*?)\s*#*\s*$')
CODE_SPAN = re.compile(r'(`+)(.+?)\1')
#: Inline links and images: [text](target) and ![alt](target), target without spaces.
LINK = re.compile(r'!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+"[^"]*")?\s*\)')


def markdown_pages() -> list[Path]:
    """README.md and every page of docs/."""
    return [README, *sorted(DOCS.glob('*.md'))]


def prose_lines(text: str) -> list[tuple[int, str]]:
    """(line number, line) of the lines outside fenced code blocks."""
    lines, fenced = [], False
    for number, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            lines.append((number, line))
    return lines


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading's Markdown text."""
    text = re.sub(r'!?\[([^\]]*)\]\([^)]*\)', r'\1', heading)  # a link's text only
    text = CODE_SPAN.sub(lambda match: match.group(2), text).replace('*', '')
    text = re.sub(r'[^\w\- ]', '', text.strip().lower())
    return text.replace(' ', '-')


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file, repeated headings numbered as GitHub does."""
    seen: dict[str, int] = {}
    result = set()
    for _, line in prose_lines(path.read_text(encoding='utf-8')):
        match = HEADING.match(line)
        if not match:
            continue
        slug = anchor(match.group(2))
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        result.add(slug if count == 0 else f'{slug}-{count}')
    return result


def relative_links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of the relative links and images of a Markdown file."""
    links = []
    for number, line in prose_lines(path.read_text(encoding='utf-8')):
        for target in LINK.findall(CODE_SPAN.sub('', line)):
            if not re.match(r'^[a-z][a-z0-9+.-]*:', target, re.IGNORECASE):  # http:, mailto:
                links.append((number, target))
    return links


def test_anchor_follows_github():
    assert anchor('Several robots on one `ROS_DOMAIN_ID`') == 'several-robots-on-one-ros_domain_id'
    assert anchor('Which gait: `gait: auto`') == 'which-gait-gait-auto'
    assert anchor("The graph's CPU, and walks under load") == 'the-graphs-cpu-and-walks-under-load'
    assert anchor('`/joint_commands`') == 'joint_commands'


def test_readme_is_short():
    lines = README.read_text(encoding='utf-8').count('\n')
    assert lines < MAX_README_LINES, f'README.md has {lines} lines; move reference to docs/'


def test_readme_keeps_the_two_commands_and_ci_runs_the_test_command():
    text = README.read_text(encoding='utf-8')
    for command in (MAIN_JOB_COMMAND, TEST_COMMAND):
        assert f'```sh\n{command}\n```\n' in text, command
    head = text[:text.index('\n## ', text.index('\n## ') + 1)]
    assert MAIN_JOB_COMMAND in head and TEST_COMMAND in head, 'the two commands come first'
    ci_run = (REPO / '.ci' / 'run').read_text(encoding='utf-8')
    assert f'\n{TEST_COMMAND} ' in ci_run


@pytest.mark.parametrize('page', markdown_pages(), ids=lambda path: path.name)
def test_every_relative_link_resolves(page):
    broken = []
    for number, target in relative_links(page):
        file_part, _, fragment = target.partition('#')
        destination = (page.parent / file_part).resolve() if file_part else page
        if not destination.exists():
            broken.append(f'{page.name}:{number}: {target}: no file {destination}')
        elif fragment and destination.suffix == '.md' and fragment not in anchors(destination):
            broken.append(f'{page.name}:{number}: {target}: no heading #{fragment}')
    assert broken == []


def test_every_docs_page_is_one_click_from_the_readme():
    linked = {
        (README.parent / target.partition('#')[0]).resolve()
        for _, target in relative_links(README)
    }
    missing = [path.name for path in DOCS.glob('*.md') if path.resolve() not in linked]
    assert missing == []
