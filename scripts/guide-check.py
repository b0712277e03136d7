"""Checks the built guide's links: every relative href or src of every page
names a file of the book, and every #fragment an id on its page. Links to
the web are listed, not fetched (CI has no network to spare). Exits 1
naming each broken link and its page. Usage: python3 scripts/guide-check.py
target/guide"""
import html.parser
import os
import sys
from urllib.parse import unquote, urlsplit


class Page(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.ids = [], set()

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name == "id" and value:
                self.ids.add(value)
            if name in ("href", "src") and value:
                self.links.append(value)


root = sys.argv[1]
pages = {}
for folder, _, files in os.walk(root):
    for f in files:
        if f.endswith(".html"):
            path = os.path.join(folder, f)
            p = Page()
            p.feed(open(path, encoding="utf-8").read())
            pages[os.path.normpath(path)] = p
broken, web = [], set()
for path, page in pages.items():
    if path.endswith("404.html") or path.endswith("print.html") or path.endswith("toc.html"):
        continue
    for link in page.links:
        parts = urlsplit(link)
        if parts.scheme in ("http", "https"):
            web.add(link)
            continue
        if parts.scheme or link.startswith("//"):
            continue
        target = path if not parts.path else os.path.normpath(os.path.join(os.path.dirname(path), unquote(parts.path)))
        if not os.path.exists(target):
            broken.append(f"{os.path.relpath(path, root)}: {link} (no such file)")
        elif parts.fragment and target.endswith(".html") and target in pages and unquote(parts.fragment) not in pages[target].ids:
            broken.append(f"{os.path.relpath(path, root)}: {link} (no such anchor)")
for link in sorted(web):
    print(f"web link (not fetched): {link}")
for b in broken:
    print(f"broken: {b}")
print(f"{len(pages)} pages, {len(broken)} broken links")
sys.exit(1 if broken else 0)
