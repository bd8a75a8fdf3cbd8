"""amr_common.world: worlds and maps, and the geometry kernels that query them (no ROS import).

- world: World, the one world loader (World.load reads world files and Nav2 map files) and its
  geometric queries; world_file: the project's world YAML and the course's map JSON;
  polygons: a world file's polygons and their checks; worlds/: the bundled worlds.
- map_file: Nav2 map files (YAML + PGM/PNG) read and written with map_server's rules;
  map_export: a World exported as a map; map_vs_world: a map that is not the world.
- map_raster: rasters in the ROS map convention and a map's cells as walls; occupancy_grid:
  THE grid of a world (the planner's, the filter's, /map's); coverage_grid: the coarse cells
  of the coverage metrics; cell_grid: the cell indexing they share; distance_transform: a
  map's exact clearances.
- raycast, raster_raycast: ray casting against wall segments and through a map's cells.
"""
