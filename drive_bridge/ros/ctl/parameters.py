"""
The bridge node's parameters for ``drive_bridge_ctl``: get, set, list and describe.

A value is typed as the node declares the parameter (its descriptor's type), so ``40``
goes to a double as 40.0 and ``false`` to a bool as false; text that is not of that type,
and a read-only parameter, are refused here with nothing sent. The node checks the rest
(ranges, what may change while a motor runs) and its reason is printed when it refuses.
"""

import difflib
from typing import List

from drive_bridge.ros.ctl.session import BridgeSession
from drive_bridge.ros.ctl.values import (
    BadInput, format_value, parameter_value, Refused, TYPE_NAMES)
from rcl_interfaces.msg import Parameter as ParameterMsg, ParameterDescriptor, ParameterValue
from rclpy.parameter_client import AsyncParameterClient


class ParameterCommands:
    """The parameter services of the bridge node."""

    def __init__(self, session: BridgeSession):
        self.session = session
        self.node_name = session.full_name
        self.client = AsyncParameterClient(session.node, session.full_name)
        if not session.wait_for(self.client.services_are_ready, lambda: f'{self.node_name}/'
                                'set_parameters' in session.services()):
            raise BadInput(f'{self.node_name} offers no parameter services')

    def _answer(self, future, service: str):
        return self.session.answer(future, f'{self.node_name}/{service}')

    def names(self, prefix: str = '') -> List[str]:
        """Return the node's parameter names that start with ``prefix``, sorted."""
        response = self._answer(self.client.list_parameters(), 'list_parameters')
        return sorted(name for name in response.result.names if name.startswith(prefix))

    def descriptor(self, name: str) -> ParameterDescriptor:
        """Return the node's descriptor of ``name``; raise BadInput if it has no such one."""
        response = self._answer(self.client.describe_parameters([name]),
                                'describe_parameters')
        if not response.descriptors:
            close = difflib.get_close_matches(name, self.names(), n=3)
            hint = f': did you mean {" or ".join(close)}?' if close else \
                ' (see: param list)'
            raise BadInput(f'{self.node_name} has no parameter {name!r}{hint}')
        return response.descriptors[0]

    def values(self, names: List[str]) -> List[ParameterValue]:
        """Return the current values of ``names``."""
        return list(self._answer(self.client.get_parameters(names), 'get_parameters').values)

    def get(self, name: str) -> int:
        """Print one parameter as ``name = value (type)``."""
        self.descriptor(name)
        self._print(name, self.values([name])[0])
        return 0

    def set_value(self, name: str, text: str) -> int:
        """Set one parameter, typed as the node declares it; exit status 1 if it refuses."""
        descriptor = self.descriptor(name)
        if descriptor.read_only:
            raise BadInput(f'{name} is read-only: the node takes it from the parameters file '
                           'at start; nothing sent')
        value = parameter_value(name, text, descriptor.type)
        response = self._answer(
            self.client.set_parameters([ParameterMsg(name=name, value=value)]),
            'set_parameters')
        result = response.results[0]
        if not result.successful:
            raise Refused(f'{name} = {format_value(value)} refused by {self.node_name}: '
                          f'{result.reason}')
        self._print(name, value)
        return 0

    def list_values(self, prefix: str = '') -> int:
        """Print every parameter that starts with ``prefix``, with its value and type."""
        names = self.names(prefix)
        if not names:
            raise BadInput(f'{self.node_name} has no parameter that starts with {prefix!r}')
        for name, value in zip(names, self.values(names)):
            self._print(name, value)
        return 0

    def describe(self, name: str) -> int:
        """Print a parameter's type, whether it is read-only, and its meaning."""
        descriptor = self.descriptor(name)
        read_only = ', read-only' if descriptor.read_only else ''
        lines = [f'{name} ({TYPE_NAMES.get(descriptor.type, "?")}{read_only})']
        if descriptor.description:  # the node's descriptions end with the allowed values
            lines.append(descriptor.description)
        print('\n'.join(lines), flush=True)
        return 0

    @staticmethod
    def _print(name: str, value: ParameterValue) -> None:
        print(f'{name} = {format_value(value)} ({TYPE_NAMES.get(value.type, "?")})',
              flush=True)
