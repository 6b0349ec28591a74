"""Renderer presets (`--preset`): each renderer's documented deep AOV names and motion conventions.

A preset lists, per semantic layer of channels.py, the channel names to try in order (a layer prefix, explicit
channels, or a sum of layers such as direct + indirect); a layer a preset lists is looked up with its names only
(no generic alias: V-Ray's `diffuse` is the diffuse filter, an albedo), the others with the generic aliases, and
`--map` overrides both. Its motion entries name the renderer's per-bin motion channels and how to read them as
ranad's canonical motion (pixels per frame, x right, y down; channels.MotionSpec); `--motion-units`,
`--motion-y`, `--fps` and `--shutter` override the conversion. The README's "Renderers" section tables these
with their sources; conventions the cited pages do not state are marked there as ranad's assumption (check a
frame with `ranad info --preset NAME` and override with --map / --motion-*).
"""

from __future__ import annotations

from dataclasses import dataclass, field


def _sum(*parts) -> dict:
    return {"sum": list(parts)}


@dataclass(frozen=True)
class Preset:
    name: str
    layers: dict                     # semantic layer -> tuple of candidate values, first found wins
    motion: dict = field(default_factory=dict)             # motion_prev/motion_next -> candidate values
    motion_conversion: dict = field(default_factory=dict)  # units, fps, shutter, y (channels.mapping_options)
    sources: tuple = ()
    note: str = ""


PRESETS: dict = {p.name: p for p in (
    Preset(
        "renderman",
        layers={
            # the denoiser's AOVs (diffuse, specular, albedo, normal) and the LPE AOVs of the AOV docs
            "diffuse": ("diffuse", _sum("directDiffuse", "indirectDiffuse")),
            "specular": ("specular", _sum("directSpecular", "indirectSpecular")),
            "emission": ("emissive",),
            "albedo": ("albedo",),
            "normal": ("normal", "Nn"),
        },
        motion={"motion_next": ("forward", "motionFore"), "motion_prev": ("backward", "motionBack")},
        motion_conversion={"units": "pixels", "y": "down"},
        sources=("https://rmanwiki.pixar.com/display/REN24/Denoising",
                 "https://rmanwiki.pixar.com/display/REN/Arbitrary+Output+Variables"),
        note="motionFore/motionBack (the denoiser's forward/backward) read as raster-space pixels, y down",
    ),
    Preset(
        "arnold",
        layers={
            "diffuse": ("diffuse", _sum("diffuse_direct", "diffuse_indirect")),
            "specular": ("specular", _sum("specular_direct", "specular_indirect")),
            "emission": ("emission",),
            "albedo": ("denoise_albedo", "diffuse_albedo", "albedo"),
            "normal": ("N",),
        },
        motion={"motion_next": ("motionvector",)},
        motion_conversion={"units": "pixels", "y": "down"},
        sources=("https://help.autodesk.com/view/ARNOL/ENU/"
                 "?guid=arnold_user_guide_ac_output_aovs_ac_expression_aovs_html",
                 "https://help.autodesk.com/cloudhelp/ENU/AR-DevGuide/files/plugins/shaders/"
                 "arnold_dev_guide_shading_lighting_av_aovs_html.html"),
        note="motionvector (VECTOR2, 'screen space motion vector') read as forward pixels over the camera shutter; "
             "give --shutter for a shutter shorter than a frame",
    ),
    Preset(
        "karma",
        layers={
            "diffuse": ("combineddiffuse", _sum("directdiffuse", "indirectdiffuse"),
                        _sum("diffuse", "indirectdiffuse")),
            "specular": ("combinedglossyreflection", _sum("directglossyreflection", "indirectglossyreflection"),
                         _sum("glossyreflection", "indirectglossyreflection")),
            "emission": ("combinedemission", "emission"),
            "albedo": ("albedo",),
            "normal": ("N",),
        },
        motion={"motion_next": ("motionvector", "motionvectors")},
        motion_conversion={"units": "ndc", "y": "up"},
        sources=("https://www.sidefx.com/docs/houdini/nodes/lop/karmastandardrendervars.html",
                 "https://www.sidefx.com/docs/houdini/solaris/support/aovs.html"),
        note="motion vectors read as forward NDC displacement (x width, y height of the display window), y up",
    ),
    Preset(
        "vray",
        layers={
            "diffuse": (_sum("lighting", "GI"), _sum("VRayLighting", "VRayGlobalIllumination")),
            "specular": (_sum("reflect", "specular"), _sum("VRayReflection", "VRaySpecular"), "reflect",
                         "VRayReflection"),
            "emission": ("selfIllum", "VRaySelfIllumination"),
            "albedo": ("diffuse", "VRayDiffuseFilter"),
            "normal": ("normals", "VRayNormals"),
        },
        motion={"motion_next": ("velocity", "VRayVelocity")},
        motion_conversion={"units": "pixels", "y": "up"},
        sources=("https://docs.chaos.com/display/VMAYA/Velocity",),
        note="Velocity: motion 'between the current frame and the next frame', read as pixels (Clamp velocity "
             "off), y up; V-Ray's 'diffuse' element is the diffuse filter (an albedo)",
    ),
    Preset(
        "redshift",
        layers={
            "diffuse": (_sum("DiffuseLighting", "GI"), "DiffuseLighting"),
            "specular": (_sum("SpecularLighting", "Reflections"), "SpecularLighting", "Reflections"),
            "emission": ("Emission",),
            "albedo": ("DiffuseFilter",),
            "normal": ("N", "Normals", "BumpNormals"),
        },
        motion={"motion_next": ("MotionVectors", "MotionVector")},
        motion_conversion={"units": "pixels", "y": "up"},
        sources=("https://docs.redshift3d.com/display/RSDOCS/Integrated+AOVs",),
        note="EXR layer names as Redshift names its AOV types (Diffuse Lighting, Global Illumination, Specular "
             "Lighting, Reflections, Emission, Diffuse Filter, Motion Vectors); MotionVectors read as raw (not "
             "normalised) forward pixels, y up",
    ),
)}
