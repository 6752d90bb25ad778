"""The crtk_msgs interfaces built by the install step carry the dVRK's wire types."""

from __future__ import annotations

from rclpy.serialization import deserialize_message, serialize_message


def test_operating_state_fields_match_crtk() -> None:
    """OperatingState is {header, state, is_homed, is_busy} and survives CDR serialisation."""
    from crtk_msgs.msg import OperatingState

    assert OperatingState.get_fields_and_field_types() == {
        "header": "std_msgs/Header",
        "state": "string",
        "is_homed": "boolean",
        "is_busy": "boolean",
    }
    message = OperatingState(state="ENABLED", is_homed=True, is_busy=False)
    message.header.frame_id = "PSM1"
    back = deserialize_message(serialize_message(message), OperatingState)
    assert (back.state, back.is_homed, back.is_busy, back.header.frame_id) == ("ENABLED", True, False, "PSM1")


def test_string_stamped_fields_match_crtk() -> None:
    """StringStamped is {header, string}, the type of the dVRK's state_command."""
    from crtk_msgs.msg import StringStamped

    assert StringStamped.get_fields_and_field_types() == {"header": "std_msgs/Header", "string": "string"}
    back = deserialize_message(serialize_message(StringStamped(string="home")), StringStamped)
    assert back.string == "home"


def test_loopback_settings_are_in_force() -> None:
    """The test process runs with localhost discovery, UDPv4 and a domain id in 0..101."""
    import os

    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.environ["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"
    assert 0 <= int(os.environ["ROS_DOMAIN_ID"]) <= 101
