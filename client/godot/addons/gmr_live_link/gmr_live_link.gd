# GmrLiveLink: a gmr-server's motion, live, on a Skeleton node (Godot 3.x).
#
# It speaks the server's protocol over a WebSocket in protobuf's JSON mapping
# (ws://HOST:HTTP_PORT/ws, subprotocol gmr.stream.v1.json; docs/protocol.md):
# GDScript parses JSON natively, and Godot 3 has no protobuf runtime, so the
# add-on needs nothing beside itself. It asks for a view of `motion` (roots,
# viewpoint, dummies stripped), subscribes to it in Godot's conventions (Y up,
# -Z forward, right-handed, metres) with each joint's local transform, builds
# the Skeleton's bones from the subscription's skeleton and rest pose, and poses
# them from the newest frame every _process. A change of the view's structure
# (a root shifted while streaming, here or by anyone holding the view) rebuilds
# the bones; a lost connection is retried every `reconnect_seconds`.
#
# With `retarget_onto_skeleton`, the Skeleton's own bones are the character:
# the add-on sends them to the server as the rig (docs/retarget.md, "Live"),
# the server puts the motion on them, and the frames pose those bones, which
# keep their names, hierarchy and rests (nothing is built or cleared).
#
# Everything the server sends is checked before it is used: a message that is
# not what the protocol says is counted in `bad_messages` and dropped.
extends Node

signal link_state_changed(state)
signal skeleton_built(version, bone_count)
signal frame_applied(frame_index)
signal stream_ended(reason)

const PROTOCOL_VERSION = 1
const SUBPROTOCOL = "gmr.stream.v1.json"
const MAX_JOINTS = 4096

export var host := "127.0.0.1"
# The server's HTTP port (gmr-server --http-port; the WebSocket is at /ws).
export var port := 7480
# A token from the server's auth file; empty: anonymous. Sent in the clear:
# use it on loopback or a trusted network only.
export var token := ""
export var motion := "walk"
# Roots of the view (comma-separated joint names); empty: the motion's own.
export var roots := ""
# The motion seen from this joint (its bone frame); empty: world coordinates.
export var relative_to := ""
export var strip_dummies := false
# "godot" (Y up, -Z forward, right-handed, metres) or "native" (the file's).
export(String, "godot", "native") var conventions = "godot"
# The motion's unit in metres when the server's library does not know it
# (a BVH: 0.0254 for inches, 0.01 for centimetres); 0: the library's.
export var source_metres_per_unit := 0.0
export var speed := 1.0
export var loop := true
export var max_staleness_ms := 100
export(NodePath) var skeleton_path = NodePath("../Skeleton")
export var auto_connect := true
# The motion retargeted onto the Skeleton's own bones (a humanoid: Mixamo,
# Unreal mannequin, Godot's or Unity's humanoid names, ...; else `rig_map`,
# role -> bone name, docs/retarget.md "Maps"). No viewpoint with it.
export var retarget_onto_skeleton := false
export var rig_map := {}
export var reconnect_seconds := 2.0

# State, read-only from outside.
var state := "disconnected"       # disconnected, connecting, connected, streaming, ended
var last_error := ""
var fps := 0.0                    # frames applied per second, over the last second
var latency_ms := 0.0             # server encode to apply, on one clock (same host or synchronised)
var frames_received := 0
var frames_applied := 0
var frames_dropped := 0           # replaced here before a tick applied them, plus those the server dropped
var bad_messages := 0
var skeleton_version := 0
var frame_index := -1
var bone_count := 0
var metres_per_unit := 0.0        # the unit of what is applied (0: unknown)

var _ws: WebSocketClient = null
var _next_request := 1
var _pending := {}                # request id -> handler name
var _view_id := 0
var _subscription_id := 0
var _slots := []                  # value slot -> bone index
var _rest_inverse := []           # bone index -> rest.affine_inverse()
# Retargeting onto the Skeleton's bones, per joint of the subscription:
var _bone_of := []                # its bone
var _joint_parent := []           # its parent joint (-1: a root)
var _rest_global := []            # its bone's rest in the Skeleton's space
var _newest = null                # the newest frame not yet applied
var _retry_in := 0.0
var _heartbeat_every := 10.0
var _heartbeat_in := 0.0
var _fps_window := 0.0
var _fps_count := 0


func _ready():
	if auto_connect:
		connect_to_server()


func connect_to_server():
	close()
	_ws = WebSocketClient.new()
	if _ws.has_method("set_buffers"):
		# Room for a large skeleton's reply (about 300 bytes of JSON a joint).
		_ws.set_buffers(4096, 1024, 1024, 1024)
	_ws.connect("connection_established", self, "_on_open")
	_ws.connect("connection_closed", self, "_on_closed")
	_ws.connect("connection_error", self, "_on_error")
	_ws.connect("data_received", self, "_on_data")
	var url := "ws://%s:%d/ws" % [host, port]
	var err := _ws.connect_to_url(url, PoolStringArray([SUBPROTOCOL]))
	if err != OK:
		_fail("cannot connect to %s (error %d)" % [url, err])
		return
	_set_state("connecting")


func close():
	_drop_socket()
	if state != "ended":
		_set_state("disconnected")


func _edit(kind: String, args: Dictionary):
	if _view_id == 0:
		last_error = "%s: no view yet (state %s)" % [kind, state]
		return
	args["viewId"] = _view_id
	var body := {}
	body[kind] = args
	_send(body, "_on_view_edited")


# Root edits on the running view: the server answers with the view and pushes
# the new skeleton to the subscription, which rebuilds the bones.
func shift_root(joint: String):
	_edit("shiftRoot", {"joint": joint})


func set_roots(names: PoolStringArray):
	_edit("setRoots", {"roots": Array(names)})


# A new viewpoint: the subscription starts again from the frame shown.
func set_relative_to(joint: String):
	relative_to = joint
	if _view_id != 0:
		_send({"setCoordinates": {"viewId": _view_id, "relativeTo": joint}}, "_on_viewpoint")


func skeleton() -> Skeleton:
	return get_node_or_null(skeleton_path) as Skeleton


func _process(delta):
	_fps_window += delta
	if _fps_window >= 1.0:
		fps = _fps_count / _fps_window
		_fps_window = 0.0
		_fps_count = 0
	if _ws == null:
		if auto_connect and reconnect_seconds > 0.0 and state != "ended":
			_retry_in -= delta
			if _retry_in <= 0.0:
				connect_to_server()
		return
	var ws := _ws  # held while it polls: a handler may drop the link's reference
	ws.poll()
	if _ws == null:
		return
	if state == "connected" or state == "streaming":
		_heartbeat_in -= delta
		if _heartbeat_in <= 0.0:
			_heartbeat_in = _heartbeat_every
			_put({"heartbeat": {}})
	if _newest != null:
		_apply(_newest)
		_newest = null


func _set_state(s: String):
	if s != state:
		state = s
		emit_signal("link_state_changed", s)


func _fail(message: String):
	last_error = message
	push_warning("gmr live link: " + message)
	_drop_socket()
	_retry_in = reconnect_seconds
	if state != "ended":
		_set_state("disconnected")


# The socket's signals are disconnected first: closing it must not call back
# into a link that has already moved on (or is connecting again).
func _drop_socket():
	if _ws != null:
		for pair in [["connection_established", "_on_open"], ["connection_closed", "_on_closed"],
				["connection_error", "_on_error"], ["data_received", "_on_data"]]:
			if _ws.is_connected(pair[0], self, pair[1]):
				_ws.disconnect(pair[0], self, pair[1])
		_ws.disconnect_from_host()
		_ws = null
	_pending.clear()
	_view_id = 0
	_subscription_id = 0
	_newest = null


func _on_open(_protocol):
	_ws.get_peer(1).set_write_mode(WebSocketPeer.WRITE_MODE_TEXT)
	var hello := {"protocolVersion": PROTOCOL_VERSION, "clientName": "gmr Godot live link"}
	if token != "":
		hello["authToken"] = token
	_send({"hello": hello}, "_on_hello")


func _on_closed(_clean):
	_fail("the server closed the connection")


func _on_error():
	_fail("cannot reach ws://%s:%d/ws" % [host, port])


func _on_data():
	while _ws != null and _ws.get_peer(1).get_available_packet_count() > 0:
		var text: String = _ws.get_peer(1).get_packet().get_string_from_utf8()
		var parsed := JSON.parse(text)
		if parsed.error != OK or typeof(parsed.result) != TYPE_DICTIONARY:
			bad_messages += 1
			continue
		_on_message(parsed.result)


func _put(message: Dictionary):
	if _ws != null:
		_ws.get_peer(1).put_packet(to_json(message).to_utf8())


func _send(body: Dictionary, handler: String):
	var id := _next_request
	_next_request += 1
	_pending[id] = handler
	body["requestId"] = str(id)
	_put(body)


func _on_message(m: Dictionary):
	if m.has("frame"):
		_on_frame(m["frame"])
		return
	if m.has("skeletonChanged"):
		_on_skeleton_changed(m["skeletonChanged"])
		return
	if m.has("subscriptionEnded"):
		_on_ended(m["subscriptionEnded"])
		return
	if m.has("heartbeat"):
		return
	var id := _int(m.get("requestId", 0))
	if not _pending.has(id):
		bad_messages += 1
		return
	var handler: String = _pending[id]
	_pending.erase(id)
	if m.has("error"):
		var e = m["error"]
		var text := str(e.get("message", "")) if typeof(e) == TYPE_DICTIONARY else ""
		if handler == "_on_view_edited":
			last_error = "the server refused an edit: " + text  # the view stays as it was
			return
		if handler == "_on_retargeted":
			# The bones will not become a humanoid by asking again.
			return _end("the server cannot retarget onto the Skeleton's bones: " + text)
		_fail("the server refused %s: %s" % [handler.trim_prefix("_on_"), text])
		if handler in ["_on_view", "_on_view_ready", "_on_subscribed"]:
			_retry_in = max(reconnect_seconds, 5.0)  # a motion that is not there yet: ask again, slowly
		return
	call(handler, m)


func _on_hello(m: Dictionary):
	var reply = m.get("hello")
	if typeof(reply) != TYPE_DICTIONARY:
		return _fail("the server's Hello reply is not an object")
	var idle := _num(reply.get("idleTimeoutMs", 30000))
	_heartbeat_every = clamp(idle / 3000.0, 0.5, 10.0)
	_heartbeat_in = _heartbeat_every
	_set_state("connected")
	_send({"createView": {"motion": motion}}, "_on_view")


func _on_view(m: Dictionary):
	var view = m.get("view")
	if typeof(view) != TYPE_DICTIONARY:
		return _fail("the server's view reply is not an object")
	_view_id = _int(view.get("viewId", 0))
	var names := []
	for r in roots.split(",", false):
		names.append(r.strip_edges())
	if names.size() > 0:
		_send({"setRoots": {"viewId": _view_id, "roots": names}}, "_on_view_ready")
	if strip_dummies:
		_send({"stripDummies": {"viewId": _view_id}}, "_on_view_ready")
	if relative_to != "":
		_send({"setCoordinates": {"viewId": _view_id, "relativeTo": relative_to}}, "_on_view_ready")
	if retarget_onto_skeleton:
		var rig = skeleton_rig()
		if typeof(rig) == TYPE_STRING:
			return _end(rig)
		var r := {"viewId": _view_id, "target": rig}
		if rig_map.size() > 0:
			r["targetMap"] = rig_map
		_send({"retarget": r}, "_on_retargeted")
	_subscribe(0)


func _on_view_ready(_m: Dictionary):
	pass


func _on_retargeted(_m: Dictionary):
	pass


# The Skeleton's bones as a gmr rig (the Retarget request's `target`): one
# joint per bone, parents first, each at its rest position relative to its
# parent's in the Skeleton's space, with BVH channels; the unit is the
# Skeleton node's scale in metres. Returns a Dictionary, or a String saying
# why the bones cannot be a rig.
func skeleton_rig():
	var skel := skeleton()
	if skel == null:
		return "no Skeleton at %s" % skeleton_path
	var n := skel.get_bone_count()
	if n == 0 or n > MAX_JOINTS:
		return "the Skeleton has %d bones: nothing to retarget onto" % n
	var scale := skel.global_transform.basis.get_scale()
	if abs(scale.x - scale.y) > 1e-6 * abs(scale.x) or abs(scale.x - scale.z) > 1e-6 * abs(scale.x) or scale.x <= 0.0:
		return "the Skeleton is scaled unevenly (%s): apply its scale first" % str(scale)
	var globals := _rest_globals(skel)
	var order := _parents_first(skel)
	var index := {}
	var joints := []
	var rot := ["CHANNEL_Z_ROTATION", "CHANNEL_X_ROTATION", "CHANNEL_Y_ROTATION"]
	for b in order:
		var p: int = skel.get_bone_parent(b)
		var head: Vector3 = globals[b].origin - (globals[p].origin if p >= 0 else Vector3())
		index[b] = joints.size()
		joints.append({"name": skel.get_bone_name(b), "parent": index[p] if p >= 0 else -1, "softParent": -1,
				"offset": {"x": head.x, "y": head.y, "z": head.z},
				"channels": (["CHANNEL_X_POSITION", "CHANNEL_Y_POSITION", "CHANNEL_Z_POSITION"] + rot) if p < 0 else rot})
	return {"joints": joints, "metresPerUnit": scale.x}


# Each bone's rest in the Skeleton's space.
static func _rest_globals(skel: Skeleton) -> Array:
	var globals := []
	globals.resize(skel.get_bone_count())
	for b in _parents_first(skel):
		var p: int = skel.get_bone_parent(b)
		globals[b] = (globals[p] if p >= 0 else Transform()) * skel.get_bone_rest(b)
	return globals


# The bones, every parent before its children (Godot does not require it).
static func _parents_first(skel: Skeleton) -> Array:
	var n := skel.get_bone_count()
	var children := []
	children.resize(n)
	for b in range(n):
		children[b] = []
	var order := []
	for b in range(n):
		var p: int = skel.get_bone_parent(b)
		if p >= 0 and p < n and p != b:
			children[p].append(b)
		else:
			order.append(b)
	var k := 0
	while k < order.size():
		order += children[order[k]]
		k += 1
	return order


# After an edit, `roots` names the view's roots as they now are, so a
# reconnection builds the same forest again.
func _on_view_edited(m: Dictionary):
	var view = m.get("view")
	if typeof(view) != TYPE_DICTIONARY or typeof(view.get("skeleton")) != TYPE_DICTIONARY:
		return
	var joints = view["skeleton"].get("joints")
	if typeof(joints) != TYPE_ARRAY:
		return
	var names := []
	for j in joints:
		if typeof(j) == TYPE_DICTIONARY and _int(j.get("parent", 0)) < 0:
			names.append(str(j.get("name", "")))
	roots = PoolStringArray(names).join(",")


func _on_viewpoint(_m: Dictionary):
	if _subscription_id != 0:
		_send({"unsubscribe": {"subscriptionId": _subscription_id}}, "_on_view_edited")
		_subscription_id = 0
	_subscribe(int(max(frame_index, 0)))


func _subscribe(start_frame: int):
	var c := {}
	if retarget_onto_skeleton:
		pass  # the rig's own space and unit: the Skeleton's
	elif conventions == "godot":
		c["preset"] = "CONVENTION_PRESET_GODOT"
		if source_metres_per_unit > 0.0:
			c["sourceMetresPerUnit"] = source_metres_per_unit
	var s := {"viewId": _view_id, "startFrame": start_frame, "loop": loop, "speed": speed,
			"precision": "PRECISION_FLOAT64", "localTransforms": true, "conventions": c,
			"maxStalenessMs": max_staleness_ms}
	_send({"subscribe": s}, "_on_subscribed")


func _on_subscribed(m: Dictionary):
	var sub = m.get("subscribed")
	if typeof(sub) != TYPE_DICTIONARY:
		return _fail("the server's Subscribed reply is not an object")
	_subscription_id = _int(sub.get("subscriptionId", 0))
	if not _build(sub):
		return
	_set_state("streaming")


func _on_skeleton_changed(c):
	if typeof(c) != TYPE_DICTIONARY or _int(c.get("subscriptionId", 0)) != _subscription_id:
		bad_messages += 1
		return
	_newest = null  # a frame of the old skeleton
	_build(c)


# Stops for good (no reconnecting): what is wrong is on this side.
func _end(message: String):
	last_error = message
	push_warning("gmr live link: " + message)
	_drop_socket()
	_set_state("ended")


func _on_ended(e):
	if typeof(e) != TYPE_DICTIONARY or _int(e.get("subscriptionId", 0)) != _subscription_id:
		return
	frames_dropped += _int(e.get("framesDropped", 0))
	var reason := str(e.get("reason", ""))
	_subscription_id = 0
	emit_signal("stream_ended", reason)
	if loop:
		# A looping stream ends only when the server ends it (a library file
		# replaced, a live source gone): start again on a fresh view.
		_fail("the stream ended: " + reason)
	else:
		last_error = reason
		_set_state("ended")


# The bones from a Subscribed or SkeletonChanged message: names, parents and
# rest pose (in the subscription's conventions), and which bone each value slot
# of a frame belongs to.
func _build(msg: Dictionary) -> bool:
	var skel := skeleton()
	if skel == null:
		_fail("no Skeleton at %s" % skeleton_path)
		return false
	var sk = msg.get("skeleton")
	var joints = sk.get("joints") if typeof(sk) == TYPE_DICTIONARY else null
	var slots = msg.get("joints", [])
	if typeof(joints) != TYPE_ARRAY or joints.size() == 0 or joints.size() > MAX_JOINTS or typeof(slots) != TYPE_ARRAY:
		bad_messages += 1
		_fail("the server sent a skeleton without joints")
		return false
	var parents := []
	var rests := []
	var names := {}
	for i in range(joints.size()):
		var j = joints[i]
		if typeof(j) != TYPE_DICTIONARY:
			_fail("joint %d of the skeleton is not an object" % i)
			return false
		var parent := _int(j.get("parent", 0))
		var name := bone_name(str(j.get("name", "")))
		if parent < -1 or parent >= i or name == "" or names.has(name):
			_fail("joint %d of the skeleton (%s) has parent %d or a name already used" % [i, name, parent])
			return false
		names[name] = true
		parents.append(parent)
		rests.append(Transform(Basis(_quat(j.get("restRotation"))), _vec(j.get("restTranslation"))))
	var new_slots := []
	for k in slots:
		var b := _int(k)
		if b < 0 or b >= joints.size():
			_fail("a frame slot names joint %d of %d" % [b, joints.size()])
			return false
		new_slots.append(b)
	if new_slots.size() == 0:
		for i in range(joints.size()):
			new_slots.append(i)
	if retarget_onto_skeleton:
		return _bind(skel, msg, joints, parents, new_slots)
	skel.clear_bones()
	_rest_inverse = []
	for i in range(joints.size()):
		skel.add_bone(bone_name(str(joints[i].get("name"))))
		skel.set_bone_parent(i, parents[i])
		skel.set_bone_rest(i, rests[i])
		_rest_inverse.append(rests[i].affine_inverse())
	_slots = new_slots
	bone_count = joints.size()
	skeleton_version = _int(msg.get("skeletonVersion", 0))
	metres_per_unit = _num(sk.get("metresPerUnit", 0.0))
	if conventions == "godot" and metres_per_unit == 0.0:
		# Godot's axes, but the file's numbers: say so rather than show a giant.
		last_error = ("the unit of %s is unknown, so its numbers are the file's, not metres: set "
				+ "source_metres_per_unit, or declare the unit beside the file (X.units)") % motion
		push_warning("gmr live link: " + last_error)
	emit_signal("skeleton_built", skeleton_version, bone_count)
	return true


# The subscription's joints are the Skeleton's bones (the rig it was
# retargeted onto): each joint finds its bone by name; nothing is rebuilt.
func _bind(skel: Skeleton, msg: Dictionary, joints: Array, parents: Array, slots: Array) -> bool:
	var globals := _rest_globals(skel)
	_bone_of = []
	_rest_global = []
	for i in range(joints.size()):
		var b := skel.find_bone(str(joints[i].get("name")))
		if b < 0:
			_end("the Skeleton has no bone '%s': the view is not on this Skeleton" % str(joints[i].get("name")))
			return false
		_bone_of.append(b)
		_rest_global.append(globals[b])
	for i in range(joints.size()):
		var p: int = parents[i]
		if skel.get_bone_parent(_bone_of[i]) != (_bone_of[p] if p >= 0 else -1):
			_end("bone '%s' has another parent in the Skeleton than in the view" % skel.get_bone_name(_bone_of[i]))
			return false
	_joint_parent = parents
	_slots = slots
	bone_count = skel.get_bone_count()
	skeleton_version = _int(msg.get("skeletonVersion", 0))
	metres_per_unit = _num(msg.get("skeleton").get("metresPerUnit", 0.0))
	emit_signal("skeleton_built", skeleton_version, joints.size())
	return true


func _on_frame(f):
	if typeof(f) != TYPE_DICTIONARY:
		bad_messages += 1
		return
	if _int(f.get("subscriptionId", 0)) != _subscription_id:
		return
	if _int(f.get("skeletonVersion", 0)) != skeleton_version:
		frames_dropped += 1  # of a skeleton not (or no longer) built
		return
	frames_received += 1
	if _newest != null:
		frames_dropped += 1
	_newest = f


func _apply(f: Dictionary):
	var skel := skeleton()
	var rot = f.get("localRotationsF64")
	var tra = f.get("localTranslationsF64")
	var n := _slots.size()
	if skel == null or typeof(rot) != TYPE_ARRAY or typeof(tra) != TYPE_ARRAY or rot.size() != 4 * n \
			or tra.size() != 3 * n or skel.get_bone_count() != bone_count:
		bad_messages += 1
		return
	var locals := []
	locals.resize(n)
	for k in range(n):
		var b: int = _slots[k]
		var q := Quat(_num(rot[4 * k]), _num(rot[4 * k + 1]), _num(rot[4 * k + 2]), _num(rot[4 * k + 3]))
		var t := Vector3(_num(tra[3 * k]), _num(tra[3 * k + 1]), _num(tra[3 * k + 2]))
		var len2 := q.length_squared()
		if is_nan(len2) or is_inf(len2) or len2 < 1e-12 or is_nan(t.x + t.y + t.z) or is_inf(t.x + t.y + t.z):
			bad_messages += 1
			return
		if not q.is_normalized():
			q = q.normalized()
		locals[k] = Transform(Basis(q), t)
	if retarget_onto_skeleton:
		_pose_bones(skel, locals)
	else:
		for k in range(n):
			var b: int = _slots[k]
			# Godot poses a bone relative to its rest: global = parent * rest * pose.
			skel.set_bone_pose(b, _rest_inverse[b] * locals[k])
	frame_index = _int(f.get("frameIndex", 0))
	if f.has("serverSendTimeNs"):
		latency_ms = _ms_since(f["serverSendTimeNs"])
	frames_applied += 1
	_fps_count += 1
	emit_signal("frame_applied", frame_index)


# The rig's frame posing the Skeleton's own bones. The joints' local
# transforms compose to each joint's place and its turn from the rig's rest;
# the bone wants that turn on top of its own rest orientation there:
# global_j = [turn_j * rest_global_j.basis | place_j], and Godot's bone pose
# is what takes its parent's global and its rest to that:
# pose_j = rest_j^-1 * global_parent^-1 * global_j.
func _pose_bones(skel: Skeleton, locals: Array):
	var n := _bone_of.size()
	var by_joint := []
	by_joint.resize(n)
	for k in range(_slots.size()):
		by_joint[_slots[k]] = locals[k]
	var turn := []
	var place := []
	var want := []
	for j in range(n):
		var l = by_joint[j]
		if l == null:
			bad_messages += 1  # a frame without every joint cannot pose the bones
			return
		var p: int = _joint_parent[j]
		if p < 0:
			turn.append(l.basis)
			place.append(l.origin)
		else:
			turn.append(turn[p] * l.basis)
			place.append(place[p] + turn[p].xform(l.origin))
		want.append(Transform(turn[j] * _rest_global[j].basis, place[j]))
	for j in range(n):
		var p: int = _joint_parent[j]
		var b: int = _bone_of[j]
		var parent_global: Transform = want[p] if p >= 0 else Transform()
		skel.set_bone_pose(b, skel.get_bone_rest(b).affine_inverse() * parent_global.affine_inverse() * want[j])


# A joint's name as a Godot bone name: Godot refuses ':' and '/' in bone names
# (Mixamo's "mixamorig:Hips"), so both become '_'.
static func bone_name(joint: String) -> String:
	return joint.replace(":", "_").replace("/", "_")


# Numbers in protobuf's JSON mapping: JSON numbers, or strings for 64-bit
# integers and for NaN and the infinities. Anything else reads as 0. (Godot's
# String.to_float keeps only about 7 digits, so integer strings go through int().)
static func _num(v) -> float:
	match typeof(v):
		TYPE_REAL, TYPE_INT:
			return float(v)
		TYPE_STRING:
			if v.is_valid_integer():
				return float(int(v))
			match v:
				"NaN":
					return NAN
				"Infinity":
					return INF
				"-Infinity":
					return -INF
	return 0.0


static func _int(v) -> int:
	match typeof(v):
		TYPE_REAL, TYPE_INT:
			return int(v)
		TYPE_STRING:
			if v.is_valid_integer():
				return int(v)
	return 0


# Milliseconds from a system-clock time in nanoseconds (a 19-digit string) to
# now, without a double's rounding of the whole number.
static func _ms_since(ns) -> float:
	var s := str(ns)
	if typeof(ns) != TYPE_STRING or not s.is_valid_integer() or s.length() <= 6:
		return 0.0
	var whole_ms := int(s.substr(0, s.length() - 6))
	var part_ms := int(s.substr(s.length() - 6)) / 1.0e6
	return float(OS.get_system_time_msecs() - whole_ms) - part_ms


func _vec(v) -> Vector3:
	if typeof(v) != TYPE_DICTIONARY:
		return Vector3()
	return Vector3(_num(v.get("x", 0)), _num(v.get("y", 0)), _num(v.get("z", 0)))


func _quat(v) -> Quat:
	if typeof(v) != TYPE_DICTIONARY:
		return Quat()
	var q := Quat(_num(v.get("x", 0)), _num(v.get("y", 0)), _num(v.get("z", 0)), _num(v.get("w", 0)))
	return q.normalized() if q.length_squared() > 1e-12 else Quat()
