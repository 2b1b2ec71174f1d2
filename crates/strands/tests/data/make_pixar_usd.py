"""Writes pixar-groom.usdc and pixar-groom.usdz with Pixar's own USD
(PyPI usd-core; these were made with 26.11), so that the tests read USD
files from a writer other than the crate that reads them.

    python3 -m venv /tmp/usd && /tmp/usd/bin/pip install usd-core
    /tmp/usd/bin/python make_pixar_usd.py

The groom: /Groom translates by (1, 2, 3) and turns 90 degrees about y;
/Groom/Hair scales x by 2 and holds two linear curves, their points at
time 10 and at time 20 (one unit along z), widths per vertex. And
pixar-deep.usdc, prims nested 100 deep.
"""
import os
from pxr import Usd, UsdGeom, UsdUtils, Gf, Vt, Sdf

here = os.path.dirname(os.path.abspath(__file__))
usdc = os.path.join(here, "pixar-groom.usdc")
stage = Usd.Stage.CreateNew(usdc)
groom = UsdGeom.Xform.Define(stage, "/Groom")
groom.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
groom.AddRotateYOp().Set(90.0)
hair = UsdGeom.BasisCurves.Define(stage, "/Groom/Hair")
hair.CreateTypeAttr("linear")
hair.CreateCurveVertexCountsAttr(Vt.IntArray([3, 2]))
base = [(0, 0, 0), (0, 1, 0), (0, 2, 0), (1, 0, 0), (1, 1, 0)]
points = hair.CreatePointsAttr()
for time, dz in ((10, 0.0), (20, 1.0)):
    points.Set(Vt.Vec3fArray([Gf.Vec3f(x, y, z + dz) for x, y, z in base]), time)
widths = hair.CreateWidthsAttr(Vt.FloatArray([0.01, 0.02, 0.03, 0.04, 0.06]))
hair.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
hair.AddScaleOp().Set(Gf.Vec3f(2, 1, 1))
stage.SetDefaultPrim(groom.GetPrim())
stage.GetRootLayer().Save()
UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(usdc), os.path.join(here, "pixar-groom.usdz"))

# A stage of prims nested 100 deep, past what the reader is given.
deep = Usd.Stage.CreateNew(os.path.join(here, "pixar-deep.usdc"))
path = ""
for i in range(100):
    path += "/a%d" % i
    deep.DefinePrim(path, "Xform")
deep.GetRootLayer().Save()
