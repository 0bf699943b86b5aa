"""MkDocs hook (mkdocs.yml `hooks:`): the plots and animations of results/ become part of the
site under results/, so that a page shows a committed plot by `![...](results/fig4c.png)`
without a copy of it under docs/."""

from pathlib import Path

from mkdocs.structure.files import File

REPO = Path(__file__).resolve().parents[1]
PICTURES = (".png", ".gif")


def on_files(files, config):
    for path in sorted((REPO / "results").rglob("*")):
        if path.suffix in PICTURES:
            files.append(File(path.relative_to(REPO).as_posix(), src_dir=str(REPO),
                              dest_dir=config["site_dir"],
                              use_directory_urls=config["use_directory_urls"]))
    return files
