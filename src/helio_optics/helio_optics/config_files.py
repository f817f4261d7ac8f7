"""
Where the workspace's deployment data lives: the top-level ``config/`` folder.

``config/`` holds what describes one installation rather than one node: the rig's calibrated
geometry (``rig.yaml``), the controller's lens model, the site, the canvas and cycle-model
defaults and the Fast DDS profile for camera images. ``helio_optics`` installs those files to
``share/helio_optics/config`` beside its own node YAML, so a built workspace finds them
through the ament index; a source checkout finds them beside ``src/``.

No rclpy import: nodes, command-line tools and tests all look files up the same way.
"""

import os

CONFIG_DIR_ENV = 'HELIO_CONFIG_DIR'


def _source_config_dir():
    """Return the checkout's top-level config/ when this module runs from src/helio_optics."""
    here = os.path.dirname(os.path.abspath(__file__))
    candidate = os.path.normpath(os.path.join(here, '..', '..', '..', 'config'))
    return candidate if os.path.isdir(candidate) else None


def _installed_config_dir():
    try:
        from ament_index_python.packages import get_package_share_directory
        return os.path.join(get_package_share_directory('helio_optics'), 'config')
    except (ImportError, LookupError, OSError):
        return None


def config_directories():
    """Return the folders searched for a deployment file, first match wins."""
    directories = [os.environ.get(CONFIG_DIR_ENV), _installed_config_dir(), _source_config_dir()]
    return [d for d in directories if d]


def config_path(name, required=True):
    """
    Return the path of deployment file `name` (e.g. ``'rig.yaml'``).

    Looked up in ``$HELIO_CONFIG_DIR`` (when set), the installed
    ``share/helio_optics/config``, then the checkout's ``config/``. When none has it: raise
    FileNotFoundError naming every folder searched, or return None if not `required`.
    """
    searched = config_directories()
    for directory in searched:
        path = os.path.join(directory, name)
        if os.path.isfile(path):
            return path
    if not required:
        return None
    raise FileNotFoundError(f'deployment file {name!r} not found in {searched or "any folder"} '
                            f'(set {CONFIG_DIR_ENV} or build the workspace)')


def read_parameter_section(path, section):
    """
    Return the `section` of a ROS 2 parameter file as a flat dict (``{'a.b': value}``).

    The file is ``<node or /**>: ros__parameters: <section>: ...``; the first node entry that
    has the section is used. Raise ValueError naming the file when none has it.
    """
    import yaml

    with open(path) as stream:
        document = yaml.safe_load(stream) or {}
    for node in document.values():
        parameters = (node or {}).get('ros__parameters', {})
        if section in parameters:
            return _flatten(parameters[section])
    raise ValueError(f'{path}: no ros__parameters.{section} section')


def _flatten(tree, prefix=''):
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, prefix + key + '.'))
        else:
            flat[prefix + key] = value
    return flat
