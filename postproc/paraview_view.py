"""Open a nurbsdem run in ParaView: particles coloured by shape (categorical legend), walls
translucent, contact forces as arrows, isometric camera.

Usage (ParaView 5.10 or later; its Python, ``pvpython``)::

    pvpython postproc/paraview_view.py RESULTS_DIR                  # an interactive view
    pvpython postproc/paraview_view.py RESULTS_DIR --png out.png    # render the last time, exit
    xvfb-run -a -s "-screen 0 1280x1024x24" pvpython postproc/paraview_view.py RESULTS_DIR \
        --png out.png                                                # no display (a server)
    paraview --script=postproc/paraview_view.py                     # RESULTS_DIR = ./results

Options: ``--png FILE`` (render offscreen into FILE and exit), ``--time T`` (the time shown,
s; default the last output time), ``--size W H`` (pixels, default 1200 900).

Reads ``particles.pvd``, ``walls.pvd`` and ``contacts.pvd`` written by nurbsdem (the last two
are optional). Contact arrows start at the contact point and show the normal contact force
(``force_normal`` as written, N; particles are drawn translucent so that the arrows
inside them show); their length is proportional to the force, the largest force at the
time shown drawn :data:`ARROW_FRACTION` of the scene's diagonal long (the scale stays
fixed when the animation is played; with no contact at that time, the largest force of the
run, up to :data:`MAX_SCAN_FRAMES` frames scanned, sets it).
"""
import os
import sys

#: Shape colours, by shape id (id 1 the first; cycled): ColorBrewer "Set1" (RGB 0..1).
PALETTE = [
    (0.894, 0.102, 0.110),  # red
    (0.216, 0.494, 0.722),  # blue
    (0.302, 0.686, 0.290),  # green
    (0.596, 0.306, 0.639),  # purple
    (1.000, 0.498, 0.000),  # orange
    (1.000, 1.000, 0.200),  # yellow
    (0.651, 0.337, 0.157),  # brown
    (0.969, 0.506, 0.749),  # pink
    (0.600, 0.600, 0.600),  # grey
]
WALL_COLOUR = (0.55, 0.55, 0.60)
WALL_OPACITY = 0.25
#: Particle opacity when the run has contacts: a normal-force arrow at a contact point lies
#: inside the two bodies, so opaque particles would hide every particle-particle arrow.
PARTICLE_OPACITY = 0.6
ARROW_COLOUR = (0.1, 0.1, 0.1)
#: Length of the largest contact-force arrow, as a fraction of the scene's diagonal.
ARROW_FRACTION = 0.08
#: Output frames read for the force scale when the time shown has no contact.
MAX_SCAN_FRAMES = 50
#: Viewing direction (from the focal point towards the camera), z up: isometric.
ISO_DIRECTION = (1.0, -1.0, 1.0)


def _args(argv):
    """(folder, png, time, size) from the command line."""
    argv = [a for a in argv if not a.startswith("--script")]
    opts = {"--png": None, "--time": None}
    size = [1200, 900]
    out = []
    k = 0
    while k < len(argv):
        a = argv[k]
        if a in opts and k + 1 < len(argv):
            opts[a] = argv[k + 1]
            k += 2
        elif a == "--size" and k + 2 < len(argv):
            size = [int(argv[k + 1]), int(argv[k + 2])]
            k += 3
        elif a in ("-h", "--help"):
            print(__doc__)
            sys.exit(0)
        else:
            out.append(a)
            k += 1
    folder = out[0] if out else "results"
    t = float(opts["--time"]) if opts["--time"] is not None else None
    return folder, opts["--png"], t, size


def _set(proxy, name, value):
    """Set a property that not every ParaView version has, or whose allowed values changed
    between versions (skipped there)."""
    try:
        setattr(proxy, name, value)
    except (AttributeError, ValueError):
        pass


def _bounds(*sources):
    """Union of the data bounds (xmin, xmax, ymin, ymax, zmin, zmax) of the sources, m."""
    b = [1e300, -1e300] * 3
    for src in sources:
        sb = src.GetDataInformation().GetBounds()
        for i in range(3):
            if sb[2 * i] <= sb[2 * i + 1]:
                b[2 * i] = min(b[2 * i], sb[2 * i])
                b[2 * i + 1] = max(b[2 * i + 1], sb[2 * i + 1])
    return b if b[0] <= b[1] else [0.0, 1.0] * 3


def _go_to(time):
    """Show ``time`` (s) in every view."""
    from paraview.simple import GetAnimationScene, GetTimeKeeper

    scene = GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    _set(scene, "AnimationTime", time)
    _set(GetTimeKeeper(), "Time", time)


def _solid(display, colour):
    """No scalar colouring (works on 5.10 … current; ``ColorBy(d, None)`` fails on 5.11)."""
    display.ColorArrayName = ["POINTS", ""]
    display.DiffuseColor = list(colour)
    display.AmbientColor = list(colour)


def _unique_ints(source, array, time):
    """The distinct values of an integer point array of ``source`` at ``time``."""
    from paraview import servermanager
    from vtkmodules.util.numpy_support import vtk_to_numpy
    import numpy as np

    source.UpdatePipeline(time)
    data = servermanager.Fetch(source)
    values = set()
    blocks = [data]
    while blocks:   # a PVD reader gives one dataset, a multiblock in some versions
        d = blocks.pop()
        if d is None:
            continue
        if d.IsA("vtkMultiBlockDataSet"):
            blocks += [d.GetBlock(i) for i in range(d.GetNumberOfBlocks())]
            continue
        arr = d.GetPointData().GetArray(array)
        if arr is not None and arr.GetNumberOfTuples():
            values |= set(int(v) for v in np.unique(vtk_to_numpy(arr)))
    return sorted(values)


def _largest_force(contacts, times):
    """Largest |force_normal| (N) at the given times."""
    fmax = 0.0
    for t in times:
        contacts.UpdatePipeline(t)
        info = contacts.GetPointDataInformation().GetArray("force_normal")
        if info is not None:
            fmax = max(fmax, abs(info.GetRange(-1)[1]))
    return fmax


def _colour_by_shape(particles, display, view, shape_ids):
    """Categorical colours by ``shape_id`` with a legend entry per shape."""
    from paraview.simple import ColorBy, GetColorTransferFunction, GetScalarBar

    ColorBy(display, ("POINTS", "shape_id"))
    lut = GetColorTransferFunction("shape_id")
    lut.InterpretValuesAsCategories = 1
    _set(lut, "AnnotationsInitialized", 1)
    annotations, colours = [], []
    for sid in shape_ids:
        annotations += [str(sid), f"shape {sid}"]
        colours += list(PALETTE[(sid - 1) % len(PALETTE)])
    lut.Annotations = annotations
    lut.IndexedColors = colours
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title = "particles"
    bar.ComponentTitle = ""
    for name in ("TitleColor", "LabelColor"):
        _set(bar, name, [0.0, 0.0, 0.0])
    _set(bar, "TitleFontSize", 12)
    _set(bar, "LabelFontSize", 11)
    _set(bar, "HorizontalTitle", 1)
    _set(bar, "ScalarBarLength", min(0.8, max(0.2, 0.08 * len(shape_ids) + 0.05)))
    _set(bar, "WindowLocation", "Upper Right Corner")
    return lut


def _isometric_camera(view):
    """Look at the scene from ISO_DIRECTION, z up, orthographic, fitted to the scene."""
    from paraview.simple import ResetCamera

    ResetCamera(view)
    fp = list(view.CameraFocalPoint)
    view.CameraPosition = [fp[i] + ISO_DIRECTION[i] for i in range(3)]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.CameraParallelProjection = 1
    ResetCamera(view)


def show(folder, time=None):
    """Build the pipeline and the view for the results in ``folder``; returns (view, time)."""
    from paraview.simple import GetActiveViewOrCreate, Glyph, PVDReader, Show

    view = GetActiveViewOrCreate("RenderView")
    _set(view, "UseColorPaletteForBackground", 0)
    _set(view, "BackgroundColorMode", "Single Color")
    view.Background = [1.0, 1.0, 1.0]
    _set(view, "OrientationAxesVisibility", 1)
    _set(view, "OrientationAxesLabelColor", [0.0, 0.0, 0.0])

    particles = PVDReader(registrationName="particles",
                          FileName=os.path.join(folder, "particles.pvd"))
    times = list(particles.TimestepValues or [0.0])
    t = times[-1] if time is None else float(time)
    pdisp = Show(particles, view)
    _colour_by_shape(particles, pdisp, view, _unique_ints(particles, "shape_id", t) or [1])

    shown = [particles]
    path = os.path.join(folder, "walls.pvd")
    if os.path.exists(path):
        walls = PVDReader(registrationName="walls", FileName=path)
        wdisp = Show(walls, view)
        _solid(wdisp, WALL_COLOUR)
        wdisp.Opacity = WALL_OPACITY
        shown.append(walls)

    _go_to(t)
    _isometric_camera(view)   # fitted to particles and walls, before the arrows

    path = os.path.join(folder, "contacts.pvd")
    if os.path.exists(path):
        contacts = PVDReader(registrationName="contacts", FileName=path)
        fmax = _largest_force(contacts, [t])
        if fmax <= 0.0:   # no contact at the time shown: the scale of the whole run
            times = list(contacts.TimestepValues or [t])
            fmax = _largest_force(contacts, times[::max(1, -(-len(times) // MAX_SCAN_FRAMES))])
        for src in shown:
            src.UpdatePipeline(t)
        b = _bounds(*shown)
        diag = sum((b[2 * i + 1] - b[2 * i]) ** 2 for i in range(3)) ** 0.5
        arrows = Glyph(registrationName="contact forces", Input=contacts, GlyphType="Arrow")
        arrows.OrientationArray = ["POINTS", "force_normal"]
        arrows.ScaleArray = ["POINTS", "force_normal"]
        _set(arrows, "VectorScaleMode", "Scale by Magnitude")
        arrows.ScaleFactor = ARROW_FRACTION * diag / fmax if fmax > 0.0 else 0.0
        arrows.GlyphMode = "All Points"
        adisp = Show(arrows, view)
        _solid(adisp, ARROW_COLOUR)
        if fmax > 0.0:
            pdisp.Opacity = PARTICLE_OPACITY
    _go_to(t)
    return view, t


def main(argv):
    folder, png, time, size = _args(argv)
    from paraview.simple import Interact, Render, SaveScreenshot

    view, _ = show(folder, time)
    Render(view)
    if png:
        SaveScreenshot(png, view, ImageResolution=size)
    elif "pvpython" in os.path.basename(sys.executable).lower():
        Interact(view)  # a window until closed; the GUI (--script) needs no loop


main(sys.argv[1:])
