"""The bundled methods' six leaderboard cells as the quick preset declares them (for tests that build
presets or results rows by hand)."""
MAIN_CELLS = ("d3dgs_sharp", "d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")
LABELS = {"d3dgs_sharp": "D3DGS (sharp RGB)", "d3dgs_blur": "D3DGS (blurred RGB)",
          "deblur_d3dgs": "Deblur-D3DGS (Deblur4DGS blur model, blurred RGB)", "e2vid_d3dgs": "E2VID + D3DGS",
          "e4dgs": "E-4DGS (events)", "e4dgs_rgb": "E-4DGS (events + blurred RGB)"}
METHOD = {"d3dgs_sharp": "d3dgs", "d3dgs_blur": "d3dgs", "deblur_d3dgs": "deblur_d3dgs", "e2vid_d3dgs": "e2vid_d3dgs",
          "e4dgs": "e4dgs", "e4dgs_rgb": "e4dgs_rgb"}


def described(row: dict) -> dict:
    """A hand-built results row with the label and method its cell has in the quick preset."""
    return {"label": LABELS.get(row["cell"], row["cell"]), "method": METHOD.get(row["cell"], row["cell"]), **row}
