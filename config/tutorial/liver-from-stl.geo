// A closed organ surface (STL, e.g. exported from a CT segmentation) filled
// with linear tetrahedra for palpate-precompute: docs/tutorial-stl-to-haptics.md.
//
//   gmsh -3 config/tutorial/liver-from-stl.geo -o out/tutorial/liver.msh
//   gmsh -3 config/tutorial/liver-from-stl.geo -setstring stl "$PWD/my-organ.stl" \
//        -setnumber size 5 -o out/tutorial/my-organ.msh
//
// Gmsh writes the output file even when meshing fails: check its exit code.
//
// The steps of Gmsh's tutorial t13 and of palpate-precompute's own STL
// filling (--fill-size, lib/offline/src/mesh_io.cpp): the STL triangles are
// grouped into patches, each patch gets a parametrization, the patches are
// remeshed at the target size, and the volume they enclose is filled with
// tetrahedra. Lengths are in the STL's unit (here mm).

DefineConstant[
  // A relative path is taken from this file's directory; give an absolute
  // path with -setstring. The default is the OpenHELP liver beside the
  // checkout (docs/data.md).
  stl = {"../../../shared/data/liver/openhelp-liver.stl", Name "Parameters/STL file"},
  size = {8, Min 0.1, Name "Parameters/Largest element size (STL unit)"},
  // 180: no patch boundary at sharp edges (an organ has none worth keeping);
  // patches are split only to make them parametrizable.
  angle = {180, Name "Parameters/Angle between triangles that starts a new patch (degrees)"}
];

Merge StrCat(stl);

// Split the triangulation into patches along edges sharper than `angle`,
// keep the boundary, force each patch to be parametrizable (split further if
// needed), and rebuild a geometry (surfaces, curves) on those patches. With
// the 40 degrees of Gmsh's t13, a sharp spot of this liver's STL near
// (-93, -19, 153) mm becomes a patch 0.5 mm across: the small sizes of its
// curves spread over the surfaces (20,840 vertices at size 8 instead of
// 4,841), and even without that spreading it leaves slivers and a vertex
// held by 0.2 mm3 of tetrahedra (docs/tutorial-stl-to-haptics.md).
ClassifySurfaces{angle * Pi / 180, 1, 1, Pi};
CreateGeometry;

// The volume is everything inside the closed surface. If this fails, the
// surface is not closed or it intersects itself (see the tutorial).
Surface Loop(1) = Surface{:};
Volume(1) = {1};
Physical Volume("liver", 1) = {1};

Mesh.MeshSizeMax = size;
Mesh.MeshSizeMin = size / 4;

// MSH 2.2, like the reference meshes (docs/data.md): palpate reads 2.2 and
// 4.1 alike (through the Gmsh SDK), but a 4.1 file also stores the patches'
// parametrizations here (several times the size of the mesh itself).
Mesh.MshFileVersion = 2.2;
