# Runs inside headless Godot for tests/godot/live_link_test.py: what a hostile
# or broken server could send, handed to the add-on's message handling without
# a socket. Each case must be refused and counted (bad_messages, a failed
# link with last_error) and leave the Skeleton usable; nothing may stop the
# script. Writes one JSON object per case to GMR_OUT.
extends SceneTree

var link
var skel
var results := []


func _init():
	skel = Skeleton.new()
	skel.name = "Skeleton"
	link = load("res://addons/gmr_live_link/gmr_live_link.gd").new()
	link.auto_connect = false
	link.skeleton_path = NodePath("../Skeleton")
	root.add_child(skel)
	root.add_child(link)
	var good_joints := '[{"name":"hips","parent":-1,"restRotation":{"w":1}},' \
			+ '{"name":"mixamorig:Spine","restTranslation":{"y":0.1},"restRotation":{"w":1}}]'
	# (label, a request the link waits for or "", the message's text)
	var cases := [
		["not JSON", "", "{\"frame\": "],
		["a frame that is a number", "", "{\"frame\": 5}"],
		["a reply nobody asked for", "", "{\"requestId\":\"99\",\"view\":{}}"],
		["a skeleton whose joint is its own parent", "_on_subscribed",
				"{\"requestId\":\"1\",\"subscribed\":{\"subscriptionId\":3,\"skeleton\":{\"joints\":[{\"name\":\"a\",\"parent\":0}]}}}"],
		["two joints of one name", "_on_subscribed",
				"{\"requestId\":\"1\",\"subscribed\":{\"subscriptionId\":3,\"skeleton\":{\"joints\":[{\"name\":\"a\",\"parent\":-1},{\"name\":\"a\"}]}}}"],
		["a frame slot past the joints", "_on_subscribed",
				"{\"requestId\":\"1\",\"subscribed\":{\"subscriptionId\":3,\"joints\":[0,7],\"skeleton\":{\"joints\":" + good_joints + "}}}"],
		["a good skeleton", "_on_subscribed",
				"{\"requestId\":\"1\",\"subscribed\":{\"subscriptionId\":3,\"skeletonVersion\":2,\"skeleton\":{\"metresPerUnit\":1,\"joints\":" + good_joints + "}}}"],
		["a frame with too few values", "",
				"{\"frame\":{\"subscriptionId\":3,\"skeletonVersion\":2,\"localRotationsF64\":[0,0,0,1],\"localTranslationsF64\":[0,0,0]}}"],
		["a frame with a NaN rotation", "",
				"{\"frame\":{\"subscriptionId\":3,\"skeletonVersion\":2,\"localRotationsF64\":[0,0,0,1,\"NaN\",0,0,1],\"localTranslationsF64\":[0,0,0,0,0,0]}}"],
		["a frame with a zero rotation", "",
				"{\"frame\":{\"subscriptionId\":3,\"skeletonVersion\":2,\"localRotationsF64\":[0,0,0,1,0,0,0,0],\"localTranslationsF64\":[0,0,0,0,0,0]}}"],
		["a frame of another skeleton version", "",
				"{\"frame\":{\"subscriptionId\":3,\"skeletonVersion\":9,\"localRotationsF64\":[0,0,0,1,0,0,0,1],\"localTranslationsF64\":[0,0,0,0,1,0]}}"],
		["a good frame", "",
				"{\"frame\":{\"subscriptionId\":3,\"skeletonVersion\":2,\"frameIndex\":\"12\",\"localRotationsF64\":[0,0,0,1,0,0,0,2],\"localTranslationsF64\":[1,2,3,0,0.5,0]}}"],
	]
	for c in cases:
		var before_bad: int = link.bad_messages
		var before_dropped: int = link.frames_dropped
		link.last_error = ""
		if c[1] != "":
			link._pending[1] = c[1]
		var parsed := JSON.parse(c[2])
		if parsed.error != OK or typeof(parsed.result) != TYPE_DICTIONARY:
			link.bad_messages += 1  # as _on_data counts it
		else:
			link._on_message(parsed.result)
		if link._newest != null:
			link._apply(link._newest)
			link._newest = null
		var bones := []
		for i in range(skel.get_bone_count()):
			var o: Vector3 = skel.get_bone_global_pose(i).origin
			bones.append([skel.get_bone_name(i), o.x, o.y, o.z])
		results.append({"case": c[0], "bad": link.bad_messages - before_bad,
				"dropped": link.frames_dropped - before_dropped, "error": link.last_error, "bones": bones,
				"frame_index": link.frame_index})
	var f := File.new()
	f.open(OS.get_environment("GMR_OUT"), File.WRITE)
	f.store_string(to_json(results))
	f.close()
	quit()
