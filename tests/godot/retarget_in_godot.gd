# Runs inside headless Godot (godot3-server --path PROJECT -s res://retarget_driver.gd)
# for tests/godot/live_link_test.py: a user's character, a Skeleton built from
# GMR_BONES (a JSON list of bones, parents first: name, parent index and rest
# in the Skeleton's space as 12 numbers, basis columns x, y, z then origin),
# and the add-on's GmrLiveLink with retarget_onto_skeleton, streaming
# GMR_MOTION from the server on port GMR_PORT. Writes to GMR_OUT, for
# GMR_FRAMES applied frames, every bone's global pose (origin and basis) as
# "%.9f" strings, and the Skeleton's bones after (names and parents: they must
# be the character's own, untouched).
extends SceneTree

var link
var skel
var frames := 10
var samples := []
var deadline_ms := 0
var done := false


func _init():
	frames = int(OS.get_environment("GMR_FRAMES"))
	var f := File.new()
	f.open(OS.get_environment("GMR_BONES"), File.READ)
	var bones = parse_json(f.get_as_text())
	f.close()
	skel = Skeleton.new()
	skel.name = "Skeleton"
	var globals := []
	for i in range(bones.size()):
		var b = bones[i]
		var r = b["rest"]
		var g := Transform(Basis(Vector3(r[0], r[1], r[2]), Vector3(r[3], r[4], r[5]), Vector3(r[6], r[7], r[8])),
				Vector3(r[9], r[10], r[11]))
		globals.append(g)
		var p := int(b["parent"])
		skel.add_bone(b["name"])
		skel.set_bone_parent(i, p)
		skel.set_bone_rest(i, (globals[p].affine_inverse() * g) if p >= 0 else g)
	link = load("res://addons/gmr_live_link/gmr_live_link.gd").new()
	link.name = "GmrLiveLink"
	link.port = int(OS.get_environment("GMR_PORT"))
	link.motion = OS.get_environment("GMR_MOTION")
	link.retarget_onto_skeleton = true
	link.reconnect_seconds = 0.5
	link.skeleton_path = NodePath("../Skeleton")
	link.connect("frame_applied", self, "_on_frame")
	root.call_deferred("add_child", skel)
	root.call_deferred("add_child", link)
	deadline_ms = OS.get_ticks_msec() + 120000


func _idle(_delta):
	if done:
		return true
	if link.state == "ended":
		_finish("the link ended: " + link.last_error)
		return true
	if OS.get_ticks_msec() > deadline_ms:
		_finish("timed out (link %s: %s)" % [link.state, link.last_error])
		return true
	return false


static func _s(x: float) -> String:
	return "%.9f" % x


func _on_frame(frame_index):
	var poses := {}
	for i in range(skel.get_bone_count()):
		var g: Transform = skel.get_bone_global_pose(i)
		var row := []
		for v in [g.basis.x, g.basis.y, g.basis.z, g.origin]:
			row += [_s(v.x), _s(v.y), _s(v.z)]
		poses[skel.get_bone_name(i)] = row
	samples.append({"frame": frame_index, "poses": poses})
	if samples.size() >= frames:
		_finish("")


func _finish(error: String):
	done = true
	var bones := []
	for i in range(skel.get_bone_count()):
		bones.append([skel.get_bone_name(i), skel.get_bone_parent(i)])
	var out := {"error": error, "samples": samples, "bones": bones, "bad_messages": link.bad_messages,
			"frames_applied": link.frames_applied, "metres_per_unit": link.metres_per_unit}
	var f := File.new()
	f.open(OS.get_environment("GMR_OUT"), File.WRITE)
	f.store_string(to_json(out))
	f.close()
	quit()
