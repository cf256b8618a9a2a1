# The link's state in a corner: what it is connected to and how it streams.
extends Label

export(NodePath) var link_path = NodePath("../GmrLiveLink")


func _process(_delta):
	var link = get_node_or_null(link_path)
	if link == null:
		return
	text = "%s  %s @ %s:%d\nframe %d  %.0f fps  latency %.1f ms  dropped %d  bones %d\n%s" % [
		link.state, link.motion, link.host, link.port, link.frame_index, link.fps, link.latency_ms,
		link.frames_dropped, link.bone_count, link.last_error]
