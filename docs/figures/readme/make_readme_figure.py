"""The README's picture: the stored simple reference run (data/reference/simple) in three panels drawn with the
toolkit's own figure functions into one figure (their ``ax=``), the seed paper's stated values beside ours.

    python docs/figures/readme/make_readme_figure.py      # writes docs/figures/readme/simple_channel_paper.png
"""

from pathlib import Path

from matplotlib.figure import Figure

from analysis import figures

ROOT = Path(__file__).resolve().parents[3]
RUN = ROOT / "data" / "reference" / "simple"
OUT = Path(__file__).resolve().parent / "simple_channel_paper.png"


def main():
    fig = Figure(figsize=(13, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=[1.0, 1.25])
    figures.slice_droplets(RUN, quantity="diameter", ax=fig.add_subplot(grid[:, 0]))
    counts = fig.add_subplot(grid[0, 1])
    figures.droplet_counts(RUN, ax=counts, label="ours")
    size = fig.add_subplot(grid[1, 1], sharex=counts)
    figures.centre_diameter_velocity(RUN, ax=[size, fig.add_axes([0, 0, 0, 0], visible=False)], label="ours")
    counts.set_xlabel("")
    counts.set_title("simple: droplets in the slag (paper Fig. 15 and §4.1)", fontsize="medium")
    size.set_title("mean droplet diameter against the coalescence size limit (paper Fig. 11)", fontsize="medium")
    size.set_xlabel("time [s]")
    fig.suptitle("The seed paper's simple case with the CFD-DEM engine: the central channel (left) and the paper's "
                 "stated values beside ours (dashed)", fontsize="large")
    fig.savefig(OUT, dpi=110)
    print(OUT)


if __name__ == "__main__":
    main()
