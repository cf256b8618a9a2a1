# Registers the GmrLiveLink node with the editor (Project Settings > Plugins).
tool
extends EditorPlugin


func _enter_tree():
	add_custom_type("GmrLiveLink", "Node", preload("gmr_live_link.gd"), null)


func _exit_tree():
	remove_custom_type("GmrLiveLink")
