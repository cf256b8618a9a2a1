# Runs inside headless Godot (godot3-server --path PROJECT -s res://test_driver.gd)
# for tests/godot/live_link_test.py: a Skeleton and the add-on's GmrLiveLink
# against a gmr-server on loopback. Writes, for every frame the link applied,
# the Skeleton's global bone positions (bone global pose origins): GMR_FRAMES
# frames of the view as configured, then GMR_FRAMES after set_roots(GMR_NEW_ROOTS)
# asked mid-stream, then (GMR_RESTART=1) GMR_FRAMES after the server was
# stopped and started again on the same port. Settings come from GMR_*
# environment variables; the result goes to GMR_OUT as JSON, numbers as
# "%.9f" strings (Godot's own float printing keeps 6 digits).
extends SceneTree

var link
var skel
var frames := 10
var phase := "before"
var versions := []
var samples := []
var roots_after := []
var parents_after := {}
var restart := false
var deadline_ms := 0
var done := false
var went_down := false


func _init():
	var env := OS
	frames = int(env.get_environment("GMR_FRAMES"))
	restart = env.get_environment("GMR_RESTART") == "1"
	skel = Skeleton.new()
	skel.name = "Skeleton"
	link = load("res://addons/gmr_live_link/gmr_live_link.gd").new()
	link.name = "GmrLiveLink"
	link.port = int(env.get_environment("GMR_PORT"))
	link.motion = env.get_environment("GMR_MOTION")
	link.roots = env.get_environment("GMR_ROOTS")
	link.relative_to = env.get_environment("GMR_RELATIVE_TO")
	link.source_metres_per_unit = float(env.get_environment("GMR_MPU"))
	link.reconnect_seconds = 0.5
	link.skeleton_path = NodePath("../Skeleton")
	link.connect("frame_applied", self, "_on_frame")
	link.connect("skeleton_built", self, "_on_built")
	link.connect("link_state_changed", self, "_on_state")
	root.call_deferred("add_child", skel)
	root.call_deferred("add_child", link)
	deadline_ms = OS.get_ticks_msec() + 120000


func _idle(_delta):
	if done:
		return true
	if OS.get_ticks_msec() > deadline_ms:
		_finish("timed out in phase %s (link %s: %s)" % [phase, link.state, link.last_error])
		return true
	return false


func _on_built(version, _count):
	versions.append(version)
	if phase == "asked":
		phase = "after"
		for i in range(skel.get_bone_count()):
			var p: int = skel.get_bone_parent(i)
			parents_after[skel.get_bone_name(i)] = skel.get_bone_name(p) if p >= 0 else ""
			if p < 0:
				roots_after.append(skel.get_bone_name(i))


func _on_state(state):
	if phase == "restarting" and state == "disconnected":
		went_down = true


func _on_frame(frame_index):
	if phase == "asked" or phase == "restarting" and not went_down:
		return
	if phase == "restarting":
		phase = "reconnected"
	var heads := {}
	for i in range(skel.get_bone_count()):
		var o: Vector3 = skel.get_bone_global_pose(i).origin
		heads[skel.get_bone_name(i)] = ["%.9f" % o.x, "%.9f" % o.y, "%.9f" % o.z]
	samples.append({"phase": phase, "frame": frame_index, "version": link.skeleton_version, "heads": heads,
			"fps": link.fps, "latency_ms": link.latency_ms})
	var in_phase := 0
	for s in samples:
		if s["phase"] == phase:
			in_phase += 1
	if in_phase < frames:
		return
	if phase == "before":
		phase = "asked"
		link.set_roots(PoolStringArray(OS.get_environment("GMR_NEW_ROOTS").split(",", false)))
	elif phase == "after" and restart:
		phase = "restarting"
		var f := File.new()
		f.open(OS.get_environment("GMR_OUT") + ".restart", File.WRITE)
		f.store_string("restart the server now\n")
		f.close()
	else:
		_finish("")


func _finish(error: String):
	done = true
	var out := {"error": error, "versions": versions, "roots_after": roots_after, "parents_after": parents_after,
			"samples": samples, "frames_received": link.frames_received, "frames_applied": link.frames_applied,
			"frames_dropped": link.frames_dropped, "bad_messages": link.bad_messages, "roots_property": link.roots,
			"metres_per_unit": link.metres_per_unit, "state": link.state}
	var f := File.new()
	f.open(OS.get_environment("GMR_OUT"), File.WRITE)
	f.store_string(to_json(out))
	f.close()
	quit()
