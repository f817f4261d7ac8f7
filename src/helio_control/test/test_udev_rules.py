"""helio udev: the rule names every USB id the drivers look for, and only those."""

import argparse
import re

from helio_control.cli import command_udev
from helio_control.udev_rules import udev_rules
from helio_drivers.dobot_driver_node import DOBOT_USB_IDS
from helio_drivers.servo_driver_node import MAESTRO_USB_IDS
import pytest

RULE = re.compile(r'SUBSYSTEM=="tty", ATTRS\{idVendor\}=="([0-9a-f]{4})", '
                  r'ATTRS\{idProduct\}=="([0-9a-f]{4})"(, ENV\{ID_USB_INTERFACE_NUM\}=="00")?, '
                  r'MODE="0660", GROUP="dialout", SYMLINK\+="(helio_dobot|helio_maestro)"$')


def test_every_adapter_of_the_drivers_gets_the_dialout_group_and_a_stable_name():
    rules = [RULE.match(line) for line in udev_rules().splitlines()
             if not line.startswith('#')]
    assert all(rules), udev_rules()
    named = {(f'{m.group(1)}:{m.group(2)}', m.group(4), bool(m.group(3))) for m in rules}
    # the CH9102 of newer Magicians among them (issue 30); the Maestro's command port only
    assert named == {(i, 'helio_dobot', False) for i in DOBOT_USB_IDS} | {
        (i, 'helio_maestro', True) for i in MAESTRO_USB_IDS}
    assert ('1a86:55d4', 'helio_dobot', False) in named


def test_a_bad_usb_id_is_refused_by_name():
    with pytest.raises(ValueError, match="USB id '10c4ea60' is not"):
        udev_rules(dobot_ids=['10c4ea60'], maestro_ids=[])


def test_helio_udev_prints_the_rule(capsys):
    assert command_udev(argparse.Namespace(install=False)) == 0
    assert capsys.readouterr().out == udev_rules()
