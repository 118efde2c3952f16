"""Mesh files written by the tests themselves (binary and ASCII STL, OBJ), independent of the add-on."""
import numpy as np


def write_binary(path, V, F, header=b"binary test", normals=False):
    """A binary STL of V[F]; normals: each facet's unit normal from its float32 corners (as
    Blender's STL writer stores it), else zeros."""
    rec = np.zeros(len(F), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["v"] = V[F]
    if normals:
        T = rec["v"]
        n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        rec["n"] = n / np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]
    path.write_bytes(header.ljust(80, b" ") + np.uint32(len(F)).tobytes() + rec.tobytes())


def write_ascii(path, V, F):
    lines = ["solid test"]
    for t in F:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {x:.9g} {y:.9g} {z:.9g}" for x, y, z in V[t]]
        lines += ["    endloop", "  endfacet"]
    path.write_text("\n".join(lines + ["endsolid test"]) + "\n")


def write_obj(path, V, F):
    with open(path, "w") as fh:
        fh.writelines(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V)
        fh.writelines("f " + " ".join(str(i + 1) for i in f) + "\n" for f in F)
