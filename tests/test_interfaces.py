"""amr_common.plugins.interfaces: the reference classes implement their links; errors name gaps.

Every link of the chain is loaded by MODULE:CLASS (amr_common.plugins.loader.load_class): a
malformed spec, a module that does not import, a missing class, or a class that lacks a member
of the interface is one PluginSpecError naming the link, the spec and what is missing.
"""
from __future__ import annotations

import pytest

from amr_common.plugins import interfaces
from amr_common.plugins.loader import LINKS, PluginSpecError, load_class
from amr_common.world.world import World


class HalfLocalizer:
    """predict and correct only: not a Localizer."""

    def predict(self, v, w, dt):
        pass

    def correct(self, ranges, force=False, new_scan=True):
        return False


class PlannerWithoutWarmUp:
    def plan(self, start, goal):
        return None

    def describe(self):
        return ""


def test_the_reference_classes_implement_their_interfaces():
    from amr_control.pure_pursuit import PurePursuit
    from amr_control.wall_follower import WallFollower
    from amr_localization.particle_filter import ParticleFilter
    from amr_mapping.mapper import Mapper
    from amr_planning.planner import Planner
    world = World.load("lab02")
    built = {"controller": WallFollower(0.05), "localizer": ParticleFilter(world, seed=0),
             "planner": Planner(world), "follower": PurePursuit(0.05),
             "mapper": Mapper({})}
    for link, instance in built.items():
        interface, default = LINKS[link]
        assert load_class(default, link) is type(instance)
        assert isinstance(instance, interface), link  # runtime_checkable: every member there
    plan = built["planner"].plan(world.starts["outer"][:2], world.goals["inner_far"])
    assert isinstance(plan, interfaces.PlannedPath)


def test_every_member_is_documented():
    for link, (interface, _) in LINKS.items():
        members = interfaces.interface_members(interface)
        assert members, link
        for name, is_method in members.items():
            if is_method or isinstance(vars(interface).get(name), property):
                doc = getattr(interface, name).__doc__
                assert doc and len(doc.split()) >= 5, f"{interface.__name__}.{name}"


@pytest.mark.parametrize("link, spec, message", [
    ("localizer", "amr_localization.no_such:ParticleFilter",
     "cannot import module 'amr_localization.no_such'"),
    ("localizer", "amr_localization.particle_filter:ParticleFiltre",
     "module 'amr_localization.particle_filter' has no 'ParticleFiltre'"),
    ("localizer", f"{__name__}:HalfLocalizer",
     "has no set_scan_geometry, set_lidar_offset, lidar_offset_x_m, initialize_pose, "
     "initialize_global, map, estimate, covariance, localized, particles, global_searches, "
     "describe \\(the Localizer interface"),
    ("planner", f"{__name__}:PlannerWithoutWarmUp", "has no warm_up \\(the Planner interface"),
    ("planner", "amr_planning.planner", "must look like MODULE:CLASS, e.g. "
                                        "'amr_planning.planner:Planner'"),
    ("follower", "amr_control.wall_follower:WallFollower",
     "has no set_path, clear_path, path, arrived, state, robot_radius_m, lidar_offset_x_m "
     "\\(the PathFollower interface"),
    ("mapper", "amr_planning.planner:Planner", "has no update, pose, map_to_odom"),
])
def test_a_bad_spec_names_what_is_missing(link, spec, message):
    with pytest.raises(PluginSpecError, match=message) as error:
        load_class(spec, link)
    assert str(error.value).startswith(f"{link} '{spec}'")
    assert "\n" not in str(error.value)


def test_an_instance_attribute_declared_in_the_class_body_counts():
    class Declared:
        estimate: tuple  # set in __init__, declared here

    class Undeclared:
        def __init__(self):
            self.estimate = (0.0, 0.0, 0.0)

    class Empty:
        pass

    assert "estimate" not in interfaces.missing_members(Declared, interfaces.Localizer)
    assert "estimate" in interfaces.missing_members(Undeclared, interfaces.Localizer)
    assert len(interfaces.missing_members(Empty, interfaces.Localizer)) == len(
        interfaces.interface_members(interfaces.Localizer))
