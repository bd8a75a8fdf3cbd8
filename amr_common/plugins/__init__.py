"""amr_common.plugins: the plug-in contract, what a class must be to replace a link of the chain.

- interfaces: the links as interfaces (Controller, Localizer, Planner, PathFollower, Mapper).
- loader: a link's class from "MODULE:CLASS", checked against its interface, and `name:=value`
  overrides; PluginSpecError for a spec or an override that cannot be used.
- link_failure: what counts as a failed link, one rule for the nodes, the episodes, the scripts.
- parameter_table: name -> (default, description, rule) tables every algorithm declares.
No ROS import.
"""
