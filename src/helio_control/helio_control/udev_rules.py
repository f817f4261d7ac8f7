"""
The udev rule of helio's serial devices (issue 30): permissions and stable names.

A user who is not in the ``dialout`` group cannot open ``/dev/ttyUSB*`` or ``/dev/ttyACM*``
(the drivers then fail with "Permission denied"), and the kernel's names move between plugs.
The rule gives the arm's USB-serial bridges (the Magician's CP210x, or a CH340 or CH9102 on
other units) and the Maestro's command port (its first interface) to ``dialout`` and links
them as ``/dev/helio_dobot`` and ``/dev/helio_maestro``. The USB ids are the drivers' own
(``DOBOT_USB_IDS``, ``MAESTRO_USB_IDS``): one list for auto-detection and for udev.
"""

from helio_drivers.serial_link import parse_usb_id

RULES_PATH = '/etc/udev/rules.d/99-helio.rules'
GROUP = 'dialout'


def udev_rules(dobot_ids=None, maestro_ids=None, group=GROUP):
    """Return the text of the udev rules file for `dobot_ids` and `maestro_ids` (vid:pid)."""
    if dobot_ids is None or maestro_ids is None:
        from helio_drivers.dobot_driver_node import DOBOT_USB_IDS
        from helio_drivers.servo_driver_node import MAESTRO_USB_IDS
        dobot_ids = DOBOT_USB_IDS if dobot_ids is None else dobot_ids
        maestro_ids = MAESTRO_USB_IDS if maestro_ids is None else maestro_ids
    lines = [f"# {RULES_PATH}: helio's serial devices, for the {group} group, with stable "
             'names', '# (written by "helio udev"; reload: sudo udevadm control '
             '--reload-rules && sudo udevadm trigger)']
    for name, ids, extra in (('helio_dobot', dobot_ids, ''),
                             ('helio_maestro', maestro_ids,
                              # the command port: the first of the Maestro's two ports
                              ', ENV{ID_USB_INTERFACE_NUM}=="00"')):
        for usb_id in ids:
            # the drivers' own parser: 'vvvv:pppp', or 'vvvv' for every product of a vendor
            vendor, product = parse_usb_id(usb_id)
            match = f'ATTRS{{idVendor}}=="{vendor:04x}"' + (
                '' if product is None else f', ATTRS{{idProduct}}=="{product:04x}"')
            lines.append(f'SUBSYSTEM=="tty", {match}{extra}, MODE="0660", GROUP="{group}", '
                         f'SYMLINK+="{name}"')
    return '\n'.join(lines) + '\n'
