# Draws a Skeleton's bones as lines (a bare Skeleton has no mesh to show).
extends ImmediateGeometry

export(NodePath) var skeleton_path = NodePath("../Skeleton")


func _ready():
	var m := SpatialMaterial.new()
	m.flags_unshaded = true
	m.albedo_color = Color(0.95, 0.75, 0.2)
	material_override = m


func _process(_delta):
	var skel := get_node_or_null(skeleton_path) as Skeleton
	clear()
	if skel == null or skel.get_bone_count() < 2:
		return
	begin(Mesh.PRIMITIVE_LINES)
	for i in range(skel.get_bone_count()):
		var p := skel.get_bone_parent(i)
		if p >= 0:
			add_vertex(skel.get_bone_global_pose(p).origin)
			add_vertex(skel.get_bone_global_pose(i).origin)
	end()
