"""``pibr scenes``: list the built-in scenes, or ``--show SPEC`` to summarise any scene."""
from __future__ import annotations

import json


def register(subparsers):
    """Add the ``scenes`` command; -> its parser (pibr/scenes_cli.py adds ``--plan``, which needs the server)."""
    p = subparsers.add_parser(
        "scenes", help="list built-in scenes, or show one scene",
        description="List the built-in scenes, or summarise a scene (built-in name, .toml/.json "
                    "scene description, or asset file): objects, triangles, bounds, lights, viewer.")
    p.add_argument("--show", metavar="SPEC", help="summarise this scene instead of listing")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--up", choices=("y", "z", "auto"), default=None,
                   help="with --show ASSET: its up axis (default auto: decided from its geometry)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    if args.show:
        from .registry import with_up

        return _show(with_up(args.show, args.up), args.json)
    from .registry import DEFAULT_SCENE, available_scenes

    scenes = available_scenes()
    if args.json:
        print(json.dumps({"default": DEFAULT_SCENE, "scenes": scenes}, indent=2))
        return 0
    width = max((len(n) for n in scenes), default=0)
    for name, description in scenes.items():
        mark = " (default)" if name == DEFAULT_SCENE else ""
        print(f"{name:<{width}}  {description}{mark}")
    print("\nAlso accepted wherever a scene is asked for: a .toml/.json scene description or an asset "
          "file (.obj, .glb, .gltf, .ply, ...). See 'pibr scenes --show SPEC'.")
    return 0


def summary(scene) -> dict:
    """JSON-ready summary of a scene: counts, bounds, dynamic objects, lights, viewer."""
    dynamic = [{"name": o.name, "animation": o.animation.kind} for o in scene.objects if o.is_dynamic]
    lights = [{"kind": lt.kind, "intensity": lt.intensity} for lt in scene.lights]
    return {
        "name": scene.name,
        "description": scene.description,
        "source": scene.source,
        "objects": len(scene.objects),
        "triangles": scene.triangle_count,
        "textured_objects": sum(o.material.texture is not None for o in scene.objects),
        "bounds": [[round(float(x), 6) for x in row] for row in scene.bounds()],
        "dynamic_objects": dynamic,
        "lights": lights,
        "viewer_origin": {"position": list(scene.viewer_origin.position),
                          "orientation_wxyz": list(scene.viewer_origin.orientation)},
        "near": scene.near,
        "far": scene.far,
        "extra_view": scene.extra_view,
        "notes": list(scene.notes),
    }


def _show(spec: str, as_json: bool) -> int:
    from .registry import load_scene

    info = summary(load_scene(spec))
    if as_json:
        print(json.dumps(info, indent=2))
        return 0
    lo, hi = info["bounds"]
    vp = info["viewer_origin"]
    print(f"scene      {info['name']}  ({info['source']})")
    if info["description"]:
        print(f"           {info['description']}")
    print(f"objects    {info['objects']} ({info['textured_objects']} textured), {info['triangles']} triangles")
    print(f"bounds     min {_vec(lo)}  max {_vec(hi)}  (size {_vec([b - a for a, b in zip(lo, hi)])} m)")
    moving = ", ".join(f"{d['name']} ({d['animation']})" for d in info["dynamic_objects"]) or "none"
    print(f"dynamic    {moving}")
    lights = ", ".join(f"{lt['kind']} x{lt['intensity']:g}" for lt in info["lights"]) or "none"
    print(f"lights     {lights}")
    print(f"viewer     at {_vec(vp['position'])}, orientation (w, x, y, z) {_vec(vp['orientation_wxyz'])}")
    print(f"clip       near {info['near']:g} m, far {info['far']:g} m; extra view {'on' if info['extra_view'] else 'off'}")
    for note in info["notes"]:
        print(f"note       {note}")
    return 0


def _vec(values) -> str:
    return "(" + ", ".join(f"{float(v):.3g}" for v in values) + ")"
