#!/usr/bin/python3
"""Plots of Fig. 6 (Shotton et al. 2011) from the CSVs written by docs/training/fig6.sh.

usage: /usr/bin/python3 docs/training/plot_fig6.py [CSV_DIR]   (default: this script's folder)

Reads CSV_DIR/fig6a_images.csv, fig6b_depth.csv, fig6c_offset.csv and writes
fig6a_images.png, fig6b_depth.png, fig6c_offset.png next to them: average per-class accuracy (%)
on held-out frames against training images per tree (log axis), tree depth and maximum probe
offset (pixel*m), as in the paper's Fig. 6. Needs matplotlib (Debian's python3-matplotlib).
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"plot_fig6: cannot read {path}: {e.strerror}")
    if not rows:
        sys.exit(f"plot_fig6: {path} has no rows")
    need = ["images_per_tree", "max_depth", "max_offset", "test_avg_class_acc", "train_avg_class_acc"]
    for col in need:
        if col not in rows[0]:
            sys.exit(f"plot_fig6: {path}: no column '{col}'")
    return rows


def num(row, col):
    return float(row[col])


def style(ax, xlabel, title):
    ax.set_xlabel(xlabel)
    ax.set_ylabel("Average per-class accuracy (%)")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))

    rows = read(os.path.join(folder, "fig6a_images.csv"))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    x = [num(r, "images_per_tree") for r in rows]
    ax.plot(x, [num(r, "test_avg_class_acc") for r in rows], "o-", color="tab:blue",
            label="test (held-out clips)")
    ax.plot(x, [num(r, "train_avg_class_acc") for r in rows], "s--", color="tab:gray",
            label="training frames")
    ax.set_xscale("log")
    ax.set_xticks(x)
    ax.set_xticklabels([str(int(v)) for v in x])
    style(ax, "Number of training images per tree (log scale)",
          f"(a) depth {rows[0]['max_depth']}, offset {rows[0]['max_offset']} pixel*m")
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "fig6a_images.png"), dpi=110)
    plt.close(fig)

    rows = read(os.path.join(folder, "fig6b_depth.csv"))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    counts = sorted({int(num(r, "images_per_tree")) for r in rows})
    colors = ["tab:red", "tab:blue", "tab:green", "tab:purple"]
    for i, n in enumerate(counts):
        sub = sorted((r for r in rows if int(num(r, "images_per_tree")) == n),
                     key=lambda r: num(r, "max_depth"))
        d = [num(r, "max_depth") for r in sub]
        c = colors[i % len(colors)]
        ax.plot(d, [num(r, "test_avg_class_acc") for r in sub], "o-", color=c,
                label=f"{n} images: test")
        ax.plot(d, [num(r, "train_avg_class_acc") for r in sub], "s--", color=c, alpha=0.6,
                label=f"{n} images: training frames")
    style(ax, "Depth of trees", f"(b) offset {rows[0]['max_offset']} pixel*m")
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "fig6b_depth.png"), dpi=110)
    plt.close(fig)

    rows = sorted(read(os.path.join(folder, "fig6c_offset.csv")), key=lambda r: num(r, "max_offset"))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    x = [num(r, "max_offset") for r in rows]
    ax.plot(x, [num(r, "test_avg_class_acc") for r in rows], "o-", color="tab:blue",
            label="test (held-out clips)")
    ax.plot(x, [num(r, "train_avg_class_acc") for r in rows], "s--", color="tab:gray",
            label="training frames")
    style(ax, "Maximum probe offset (pixel meters)",
          f"(c) {rows[0]['images_per_tree']} images, depth {rows[0]['max_depth']}")
    fig.tight_layout()
    fig.savefig(os.path.join(folder, "fig6c_offset.png"), dpi=110)
    plt.close(fig)
    print(f"plot_fig6: wrote fig6a_images.png, fig6b_depth.png, fig6c_offset.png in {folder}")


if __name__ == "__main__":
    main()
