"""gmr live link: a Blender add-on that drives an armature from a gmr-server
subscription (the README's "Live link" says how to install it).

Needs the gmr_client package (client/python, built into build/python) and
Debian's python3-protobuf and python3-numpy, which Debian's Blender (it runs
the system Python) imports. Where gmr_client is not on Blender's path, the
add-on's preferences (or $GMR_CLIENT_PATH) name the folder that holds it.
"""

bl_info = {
    "name": "gmr live link",
    "author": "gmr",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > gmr",
    "description": "Stream a motion from gmr-server onto an armature (built for it or your own character), "
                   "from any root or joint's viewpoint",
    "category": "Animation",
}

import os
import sys

import bpy


def _import_client(extra_path=""):
    for path in (extra_path, os.environ.get("GMR_CLIENT_PATH", "")):
        if path and path not in sys.path and os.path.isdir(path):
            sys.path.insert(0, path)
    from . import link  # noqa: F401  (imports gmr_client)
    return link


_link = None   # the LiveLink of this Blender session
_status = "not connected"
_motions = []  # the server's motions as enum items (kept here: Blender needs the strings to stay alive)


def _prefs():
    addon = bpy.context.preferences.addons.get(__name__)
    return addon.preferences if addon else None


def _motion_items(self, context):
    return _motions or [("", "(connect first)", "")]


class GmrPreferences(bpy.types.AddonPreferences):
    bl_idname = __name__
    client_path: bpy.props.StringProperty(name="gmr_client folder", subtype="DIR_PATH",
                                          description="Folder holding the gmr_client package (e.g. gmr's build/python)")

    def draw(self, context):
        self.layout.prop(self, "client_path")


class GmrSettings(bpy.types.PropertyGroup):
    host: bpy.props.StringProperty(name="Host", default="127.0.0.1")
    port: bpy.props.IntProperty(name="Port", default=7400, min=1, max=65535)
    token: bpy.props.StringProperty(name="Token", subtype="PASSWORD")
    motion: bpy.props.EnumProperty(name="Motion", items=_motion_items)
    roots: bpy.props.StringProperty(name="Roots", description="Joints to be the roots, comma-separated (empty: the file's)")
    viewpoint: bpy.props.StringProperty(name="Viewpoint", description="See the motion from this joint (empty: world)")
    rate_hz: bpy.props.FloatProperty(name="Rate", default=0.0, min=0.0, description="Frames per second (0: the motion's)")
    record: bpy.props.BoolProperty(name="Record into an Action", default=False)
    retarget: bpy.props.BoolProperty(
        name="Onto the selected armature",
        description="The server puts the motion on the selected armature (your character, a humanoid rig) "
                    "instead of building one from the capture skeleton (docs/retarget.md)")


def _tick():
    """The timer: applies what arrived and comes back 1/120 s later; never blocks."""
    global _status
    if _link is None or _link.sub is None:
        return None
    try:
        _link.record = bpy.context.scene.gmr.record
        _link.tick()
    except Exception as e:  # a broken connection: stop the timer, say why
        _status = f"stopped: {e}"
        return None
    if _link.sub.ended is not None:
        _status = f"ended: {_link.sub.ended['reason']}"
        return None
    return 1.0 / 120.0


class GMR_OT_connect(bpy.types.Operator):
    bl_idname = "gmr.connect"
    bl_label = "Connect"
    bl_description = "Connect to gmr-server and list its motions"

    def execute(self, context):
        global _link, _status
        s = context.scene.gmr
        prefs = _prefs()
        try:
            link = _import_client(prefs.client_path if prefs else "")
            if _link is not None:
                _link.close()
            _link = link.LiveLink(s.host, s.port, token=s.token)
            _motions[:] = [(m.name, m.name, f"{m.joint_count} joints, {m.frame_count} frames")
                           for m in _link.motions()]
        except Exception as e:
            _status = f"cannot connect: {e}"
            self.report({"ERROR"}, _status)
            return {"CANCELLED"}
        _status = f"connected to {s.host}:{s.port}"
        return {"FINISHED"}


class GMR_OT_start(bpy.types.Operator):
    bl_idname = "gmr.start"
    bl_label = "Stream"
    bl_description = "Build the armature of the chosen view and drive it live"

    def execute(self, context):
        global _status
        s = context.scene.gmr
        if _link is None:
            self.report({"ERROR"}, "connect first")
            return {"CANCELLED"}
        roots = [r.strip() for r in s.roots.split(",") if r.strip()]
        target = None
        if s.retarget:
            target = context.active_object
            if target is None or target.type != "ARMATURE":
                self.report({"ERROR"}, "select the armature to retarget onto")
                return {"CANCELLED"}
        try:
            _link.open(s.motion, roots=roots, viewpoint=s.viewpoint.strip(), rate_hz=s.rate_hz, target=target)
        except Exception as e:
            _status = str(e)
            self.report({"ERROR"}, _status)
            return {"CANCELLED"}
        if not bpy.app.timers.is_registered(_tick):
            bpy.app.timers.register(_tick, first_interval=0.0)
        _status = f"streaming {s.motion}" + (f" on {target.name}" if target is not None else "")
        return {"FINISHED"}


class GMR_OT_stop(bpy.types.Operator):
    bl_idname = "gmr.stop"
    bl_label = "Stop"

    def execute(self, context):
        global _status
        if bpy.app.timers.is_registered(_tick):
            bpy.app.timers.unregister(_tick)
        if _link is not None:
            _link.close_stream()
        _status = "stopped"
        return {"FINISHED"}


class GMR_OT_apply_view(bpy.types.Operator):
    bl_idname = "gmr.apply_view"
    bl_label = "Apply roots and viewpoint"
    bl_description = "Ask the server for these roots and this viewpoint; the armature follows the new skeleton"

    def execute(self, context):
        s = context.scene.gmr
        if _link is None or _link.view is None:
            self.report({"ERROR"}, "stream first")
            return {"CANCELLED"}
        try:
            roots = [r.strip() for r in s.roots.split(",") if r.strip()]
            if roots:
                _link.set_roots(roots)
            _link.set_viewpoint(s.viewpoint.strip())
        except Exception as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class GMR_PT_panel(bpy.types.Panel):
    bl_label = "gmr live link"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "gmr"

    def draw(self, context):
        s = context.scene.gmr
        col = self.layout.column()
        col.prop(s, "host")
        col.prop(s, "port")
        col.prop(s, "token")
        col.operator("gmr.connect")
        col.prop(s, "motion")
        col.prop(s, "roots")
        col.prop(s, "viewpoint")
        col.prop(s, "rate_hz")
        col.prop(s, "record")
        col.prop(s, "retarget")
        row = col.row()
        row.operator("gmr.start")
        row.operator("gmr.stop")
        col.operator("gmr.apply_view")
        col.label(text=_status)
        if _link is not None and _link.last_frame is not None:
            col.label(text=f"frame {_link.last_frame.frame_index}, skeleton v{_link.version}, "
                           f"{_link.frames_applied} applied")


classes = (GmrPreferences, GmrSettings, GMR_OT_connect, GMR_OT_start, GMR_OT_stop, GMR_OT_apply_view, GMR_PT_panel)


def register():
    for c in classes:
        bpy.utils.register_class(c)
    bpy.types.Scene.gmr = bpy.props.PointerProperty(type=GmrSettings)


def unregister():
    global _link
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)
    if _link is not None:
        _link.close()
        _link = None
    del bpy.types.Scene.gmr
    for c in reversed(classes):
        bpy.utils.unregister_class(c)
