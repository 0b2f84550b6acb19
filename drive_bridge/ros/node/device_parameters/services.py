"""
The six parameter services of a device's parameter node, served by the node itself.

``~/list_parameters``, ``~/describe_parameters``, ``~/get_parameters``,
``~/get_parameter_types``, ``~/set_parameters`` and ``~/set_parameters_atomically`` with the
``rcl_interfaces`` types, as rclpy serves them (a request naming an unknown parameter gets
an empty answer to a get, describe or get-types; a set refuses that one), for the node's own
parameters (``use_sim_time``, ``start_type_description_service``, ``refresh_period``, and
on drives ``save_to_eeprom``: rclpy's) and the device's (:mod:`.writer`, :mod:`.device`).

Every callback is a coroutine on a reentrant callback group: one awaiting the bus holds
nobody up. A get is answered from the values held; values not held yet are read (at most
:data:`MAX_READS_PER_GET` of them, within :data:`GET_WAIT_S`, so that rqt_reconfigure's 1 s
holds) and any still missing go out as ``PARAMETER_NOT_SET``.
"""

import time
from typing import List

from drive_bridge.errors import DriveBridgeError
from drive_bridge.ros.node.device_parameters import messages
from drive_bridge.ros.node.device_parameters.device import DeviceParameters
from drive_bridge.ros.node.device_parameters.writer import DeviceWriter
from drive_bridge.ros.node.service_calls import ServiceCalls
from rcl_interfaces.msg import (
    ListParametersResult, Parameter as ParameterMessage, SetParametersResult)
from rcl_interfaces.srv import (
    DescribeParameters, GetParameters, GetParameterTypes, ListParameters, SetParameters,
    SetParametersAtomically)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_parameters

GET_WAIT_S = 0.7  # a get waits this long at most for values not held (rqt gives 1 s)
MAX_READS_PER_GET = 8  # values read for one get at most: the rest of the line is polling's


class ParameterServices:
    """The parameter services of one device's parameter node."""

    def __init__(self, node: Node, device: DeviceParameters, writer: DeviceWriter,
                 calls: ServiceCalls):
        self._node = node
        self._device = device
        self._writer = writer
        self._calls = calls
        group = calls.callback_group
        for kind, suffix, callback in (
                (ListParameters, 'list_parameters', self._list),
                (DescribeParameters, 'describe_parameters', self._describe),
                (GetParameters, 'get_parameters', self._get),
                (GetParameterTypes, 'get_parameter_types', self._get_types),
                (SetParameters, 'set_parameters', self._set),
                (SetParametersAtomically, 'set_parameters_atomically', self._set_atomically)):
            node.create_service(kind, f'~/{suffix}', callback,
                                qos_profile=qos_profile_parameters, callback_group=group)

    def _local(self, name: str) -> bool:
        return self._node.has_parameter(name)

    def _known(self, names) -> bool:
        return all(self._local(name) or self._device.find(name) for name in names)

    async def _list(self, request, response):
        names = self._node.list_parameters([], 0).names + \
            [parameter.name for parameter in self._device.parameters]
        result = ListParametersResult()
        for name in names:
            depth_ok = request.depth == 0 or name.count('.') < request.depth
            wanted = not request.prefixes or any(
                name == prefix or name.startswith(prefix + '.') for prefix in request.prefixes)
            if depth_ok and wanted:
                result.names.append(name)
        response.result = result
        return response

    async def _describe(self, request, response):
        if not self._known(request.names):
            return response
        for name in request.names:
            if self._local(name):
                response.descriptors.append(self._node.describe_parameter(name))
            else:
                parameter = self._device.find(name)
                cache = self._device.cache
                response.descriptors.append(messages.descriptor(
                    parameter, cache.age_s(parameter.number), cache.error(parameter.number)))
        return response

    async def _get_types(self, request, response):
        if not self._known(request.names):
            return response
        response.types = [self._node.get_parameter_type(name) if self._local(name) else
                          messages.TYPES[self._device.find(name).kind]
                          for name in request.names]
        return response

    async def _get(self, request, response):
        if not self._known(request.names):
            return response
        if self._device.online():
            await self._read_missing(request.names)
        for name in request.names:
            if self._local(name):
                response.values.append(self._node.get_parameter(name).get_parameter_value())
            else:
                parameter = self._device.find(name)
                response.values.append(messages.value_message(
                    parameter, self._device.value(parameter)))
        return response

    async def _read_missing(self, names: List[str]) -> None:
        """Read values not held yet (a few, within GET_WAIT_S); the refresh does the rest."""
        missing = [parameter for parameter in (self._device.find(name) for name in names
                                               if not self._local(name))
                   if self._device.value(parameter) is None][:MAX_READS_PER_GET]
        deadline = time.monotonic() + GET_WAIT_S
        reads = [(parameter, self._device.read(parameter)) for parameter in missing]
        for parameter, future in reads:
            try:
                await self._calls.answer_of(future, f'read {parameter.name}',
                                            max(0.0, deadline - time.monotonic()))
            except DriveBridgeError:
                continue

    async def _set(self, request, response):
        for message in request.parameters:
            response.results.append(await self._set_one(message.name, message.value))
        return response

    async def _set_one(self, name: str, value_message) -> SetParametersResult:
        if self._local(name):
            return self._set_local(name, value_message)
        parameter = self._device.find(name)
        if parameter is None:
            return SetParametersResult(successful=False, reason=self._unknown(name))
        value = messages.python_value(value_message)
        return await self._writer.set_value(parameter, value)

    def _set_local(self, name: str, value_message) -> SetParametersResult:
        """Set one of the node's own parameters, as rclpy does; read-only and unchanged: ok."""
        given = Parameter.from_parameter_msg(ParameterMessage(name=name, value=value_message))
        if self._node.describe_parameter(name).read_only and \
                self._node.get_parameter(name).value == given.value:
            return SetParametersResult(successful=True, reason='unchanged (read-only)')
        return self._node.set_parameters([given])[0]

    async def _set_atomically(self, request, response):
        """Check every value first; refuse all if one is refused; then write in order."""
        for message in request.parameters:
            reason = ''
            if not self._local(message.name):
                parameter = self._device.find(message.name)
                reason = self._unknown(message.name) if parameter is None else \
                    await self._writer.refusal(parameter,
                                               messages.python_value(message.value))
            if reason:
                response.result = SetParametersResult(
                    successful=False, reason=f'{reason} (none of the {len(request.parameters)} '
                    'set: refused as a whole)')
                return response
        done: List[str] = []
        for message in request.parameters:
            result = await self._set_one(message.name, message.value)
            if not result.successful:
                written = ', '.join(done) or 'none'
                response.result = SetParametersResult(
                    successful=False, reason=f'{result.reason} (set before it, and not undone: '
                    f'{written})')
                return response
            done.append(message.name)
        response.result = SetParametersResult(successful=True)
        return response

    def _unknown(self, name: str) -> str:
        return f'{name} is not a parameter of {self._device.name} (ros2 param list shows ' \
            'them): nothing written'
