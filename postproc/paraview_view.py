"""Open a nurbsdem run in ParaView: particles coloured by shape, walls translucent, contact
forces as arrows.

Usage (ParaView's Python)::

    pvpython postproc/paraview_view.py RESULTS_DIR            # opens an interactive view
    pvpython postproc/paraview_view.py RESULTS_DIR --png out.png   # renders the last time
    paraview --script=postproc/paraview_view.py                # RESULTS_DIR defaults to ./results

Reads ``particles.pvd``, ``walls.pvd`` and ``contacts.pvd`` written by nurbsdem.
"""
import os
import sys

from paraview.simple import (ColorBy, GetActiveViewOrCreate, GetAnimationScene,
                             GetColorTransferFunction, Glyph, Interact, PVDReader, Render,
                             ResetCamera, SaveScreenshot, Show)


def _args():
    argv = [a for a in sys.argv[1:] if not a.startswith("--script")]
    png = None
    if "--png" in argv:
        k = argv.index("--png")
        png = argv[k + 1]
        del argv[k:k + 2]
    folder = argv[0] if argv else "results"
    return folder, png


def main():
    folder, png = _args()
    view = GetActiveViewOrCreate("RenderView")

    particles = PVDReader(registrationName="particles", FileName=os.path.join(folder, "particles.pvd"))
    pdisp = Show(particles, view)
    ColorBy(pdisp, ("POINTS", "shape_id"))
    lut = GetColorTransferFunction("shape_id")
    lut.ApplyPreset("Set1", True)
    pdisp.SetScalarBarVisibility(view, True)

    walls = PVDReader(registrationName="walls", FileName=os.path.join(folder, "walls.pvd"))
    wdisp = Show(walls, view)
    ColorBy(wdisp, None)
    wdisp.Opacity = 0.25

    contacts = PVDReader(registrationName="contacts", FileName=os.path.join(folder, "contacts.pvd"))
    arrows = Glyph(registrationName="contact forces", Input=contacts, GlyphType="Arrow")
    arrows.OrientationArray = ["POINTS", "force_normal"]
    arrows.ScaleArray = ["POINTS", "force_normal"]
    arrows.ScaleFactor = 0.002  # m per N
    arrows.GlyphMode = "All Points"
    adisp = Show(arrows, view)
    ColorBy(adisp, ("POINTS", "degenerated"))

    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    ResetCamera(view)
    if png:
        scene.AnimationTime = scene.EndTime
        Render(view)
        SaveScreenshot(png, view, ImageResolution=[1200, 900])
    else:
        Render(view)
        if "pvpython" in os.path.basename(sys.executable).lower():
            Interact(view)  # a window until closed; the GUI (--script) needs no loop


main()
