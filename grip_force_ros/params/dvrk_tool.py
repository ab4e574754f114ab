"""Instrument facts from a dVRK tool file (sawIntuitiveResearchKit ``share/tool/*.json``).

``grip-force import-dvrk-tool FILE.json --base X.yaml --out Y.yaml`` takes from the tool
file what the dVRK knows about the jaw and keeps everything else (the cable and friction
model, the motor, the other limits, the gains) from the base instrument file:

| tool file | parameter | what it is |
|---|---|---|
| ``jaw.qmin``, ``jaw.qmax`` | ``jaw_angle_min``, ``jaw_angle_max`` | the jaw's range (rad); qmin below 0 lets the jaw squeeze |
| ``jaw.ftmax`` | ``dvrk_jaw_effort_max`` | the jaw effort limit (N*m) |
| ``coupling.ActuatorToJointPosition`` jaw row ``(0, 0, -c, c)`` | ``dvrk_jaw_coupling`` | c, the dVRK's jaw effort -> actuator torque factor |
| same matrix, yaw row's pitch entry over the pitch row's | ``wrist_finger_coupling`` | blade rotation per rad of wrist pitch with the jaw disks held (the paper's wrist-finger coupling); the sign stays the base file's: the model has one blade, the dVRK two of opposite sign |

Tool files are JSON with ``//`` and ``/* */`` comments, stripped before parsing. Every
imported number carries its source in the YAML comment of its line.
"""  # noqa: E501 - Markdown table rows are kept whole
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from grip_force_ros.params.schema import ParameterError

#: Rows of ``coupling.ActuatorToJointPosition`` (tool joints) and its columns (actuators 4..7).
ROLL, PITCH, YAW, JAW = range(4)


def strip_comments(text: str) -> str:
    """Remove ``//`` line and ``/* */`` block comments outside JSON strings."""
    out, i, n = [], 0, len(text)
    in_string = False
    while i < n:
        c = text[i]
        if in_string:
            out.append(c)
            if c == '\\' and i + 1 < n:
                out.append(text[i + 1])
                i += 1
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
            out.append(c)
        elif text.startswith('//', i):
            end = text.find('\n', i)
            i = n if end < 0 else end
            continue
        elif text.startswith('/*', i):
            end = text.find('*/', i + 2)
            if end < 0:
                raise ParameterError('unterminated /* comment')
            i = end + 2
            continue
        else:
            out.append(c)
        i += 1
    return ''.join(out)


def read_tool_file(path: str | Path) -> dict:
    """Parse a dVRK tool file (comments stripped).

    Raises
    ------
    ParameterError
        The file cannot be read or is not JSON once its comments are stripped.
    """
    path = Path(path)
    try:
        return json.loads(strip_comments(path.read_text()))
    except (OSError, ValueError) as exc:
        raise ParameterError(f'{path}: not a dVRK tool file ({exc})') from None


def _number(doc: dict, *keys, where: str) -> float:
    value: Any = doc
    for k in keys:
        if not isinstance(value, dict) or k not in value:
            raise ParameterError(f'{where}: no {".".join(map(str, keys))}')
        value = value[k]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f'{where}: {".".join(map(str, keys))} is not a number: {value!r}')
    return float(value)


def tool_facts(doc: dict, name: str, base_wrist_finger_coupling: float = 1.0) -> dict[str, tuple]:
    """Return the parameters the tool file gives: name -> (value, source text).

    Parameters
    ----------
    doc : dict
        The parsed tool file.
    name : str
        The tool file's name, for the sources.
    base_wrist_finger_coupling : float
        The base file's coupling: its sign is kept (the model has one blade).

    Raises
    ------
    ParameterError
        A field is missing, or the jaw row is not (0, 0, -c, c) with c > 0.
    """
    qmin = _number(doc, 'jaw', 'qmin', where=name)
    qmax = _number(doc, 'jaw', 'qmax', where=name)
    ftmax = _number(doc, 'jaw', 'ftmax', where=name)
    try:
        matrix = [[float(x) for x in row] for row in doc['coupling']['ActuatorToJointPosition']]
    except (KeyError, TypeError, ValueError):
        raise ParameterError(f'{name}: no 4x4 coupling.ActuatorToJointPosition') from None
    if len(matrix) != 4 or any(len(row) != 4 for row in matrix):
        raise ParameterError(f'{name}: coupling.ActuatorToJointPosition is not 4x4')
    jaw = matrix[JAW]
    c = jaw[3]
    if not (jaw[0] == 0.0 and jaw[1] == 0.0 and c > 0.0 and jaw[2] == -c):
        raise ParameterError(f'{name}: the jaw row of coupling.ActuatorToJointPosition is {jaw}, '
                             'not (0, 0, -c, c) with c > 0 (two opposed jaw disks)')
    pitch, yaw_from_pitch = matrix[PITCH][1], matrix[YAW][1]
    if pitch == 0.0:
        raise ParameterError(f'{name}: the pitch row of coupling.ActuatorToJointPosition has 0 '
                             'on the pitch actuator')
    finger = math.copysign(abs(yaw_from_pitch / pitch), base_wrist_finger_coupling)
    src = f'dVRK tool file {name}'
    return {
        'jaw_angle_min': (qmin, f'{src}: jaw.qmin ({math.degrees(qmin):.0f} deg)'),
        'jaw_angle_max': (qmax, f'{src}: jaw.qmax ({math.degrees(qmax):.0f} deg)'),
        'dvrk_jaw_effort_max': (ftmax, f'{src}: jaw.ftmax'),
        'dvrk_jaw_coupling': (c, f'{src}: coupling.ActuatorToJointPosition jaw row (0, 0, -c, c)'),
        'wrist_finger_coupling': (
            finger, f'{src}: coupling.ActuatorToJointPosition |yaw row pitch entry '
                    f'{yaw_from_pitch:g} / pitch row {pitch:g}| (blade rotation per rad of wrist '
                    "pitch with the jaw disks held; sign of the base file: the model has one blade)"),
    }


def import_tool(tool: str | Path, base: str | Path, out: str | Path) -> dict[str, tuple]:
    """Write ``out``: the base instrument file with the tool file's jaw facts.

    Lines of the imported parameters get the new value and their source as the comment
    (the unit first, as in the shipped files); every other line stays as it is. The result
    is validated against the schema before it is written.

    Returns
    -------
    dict
        The imported parameters: name -> (value, source).

    Raises
    ------
    ParameterError
        The tool file, the base file or the result is invalid (the output is not written).
    """
    from grip_force_ros.params import SPECS, load_params_file, read_params_yaml, rewrite_instrument_file
    tool, base, out = Path(tool), Path(base), Path(out)
    base_values = read_params_yaml(base)
    load_params_file(base)                                    # the base must be valid itself
    facts = tool_facts(read_tool_file(tool), tool.name,
                       float(base_values.get('wrist_finger_coupling',
                                             SPECS['wrist_finger_coupling'].default)))
    header_start = '# dVRK facts ('
    header = (f'{header_start}jaw limits, jaw effort limit, jaw and pitch couplings) imported from '
              f'{tool.name} by `grip-force import-dvrk-tool`; every other number from {base.name}')
    rewrite_instrument_file(base, out, facts, header, replaces=header_start)
    return facts
