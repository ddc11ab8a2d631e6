"""Launch descriptions: modules with `generate_nodes(ctx) -> list[NodeSpec]` (see launcher)."""
