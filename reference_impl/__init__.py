"""Reference implementations built on the robogs format: reconstruction and physics."""
