// A VDA 5050 2.0.0 master controller that nobody here wrote: vda-5050-lib's MasterController
// (Siemens), driven by the tests through JSON lines.
//
//   node master.mjs --host 127.0.0.1 --port 1883 --interface uagv --manufacturer M [--visualization]
//   (or VDA5050_HOST, VDA5050_PORT, VDA5050_INTERFACE, VDA5050_MANUFACTURER)
//
// stdin, one command a line (an optional "id" is echoed in the answer):
//   {"cmd":"track","serialNumber":"s1"}                      the AGV's last connection state
//   {"cmd":"order","serialNumber":"s1","order":{...}}        assignOrder (headerless order)
//   {"cmd":"instantActions","serialNumber":"s1","actions":[...]}
//   {"cmd":"quit"}                                           (so does the end of stdin)
// stdout, one event a line, flushed as it happens: {"event": NAME, "t": ISO time, ...}:
//   ready, client (the master's own link), connection, state, factsheet, visualization,
//   tracked, orderAssigned, orderDiscarded, orderProcessed, nodeTraversed, edgeTraversing,
//   edgeTraversed, actionStateChanged, instantActionsSent, instantActionStateChanged,
//   instantActionError, dropped (an inbound message the library rejected, with its reason),
//   libraryError, commandError, handlerError, uncaught, fatal, stopped.
// Nothing ends this process without a line saying why.

import { createInterface } from "node:readline";
import { format, parseArgs } from "node:util";
import lib from "vda-5050-lib"; // CommonJS: its named exports come through the default

const { MasterController, Topic } = lib;
const VDA_VERSION = "2.0.0"; // the library compares a message's version with this verbatim

function emit(event, fields = {}) {
    // process.stdout on a pipe is synchronous on Linux: the line is out when this returns
    process.stdout.write(`${JSON.stringify({ event, t: new Date().toISOString(), ...fields })}\n`);
}

function describe(error) {
    return error instanceof Error ? error.message : String(error);
}

// The library reports an inbound message that fails its validation only with console.error
// ("Drop inbound message on MQTT topic %s with error: %s"); make that an event.
console.error = (...args) => {
    if (typeof args[0] === "string" && args[0].startsWith("Drop inbound message")) {
        emit("dropped", { mqttTopic: args[1], reason: String(args[2]) });
    } else {
        emit("libraryError", { message: format(...args) });
    }
};
process.on("uncaughtException", (error) => emit("uncaught", { message: describe(error), stack: error?.stack }));
process.on("unhandledRejection", (error) => emit("uncaught", { message: describe(error), stack: error?.stack }));

// A callback's own error must not become the library's (it would rethrow it from the MQTT
// client's message handler).
function guard(name, callback) {
    return (...args) => {
        try {
            callback(...args);
        } catch (error) {
            emit("handlerError", { handler: name, message: describe(error) });
        }
    };
}

function options() {
    const { values } = parseArgs({
        options: {
            host: { type: "string", default: process.env.VDA5050_HOST ?? "127.0.0.1" },
            port: { type: "string", default: process.env.VDA5050_PORT ?? "1883" },
            interface: { type: "string", default: process.env.VDA5050_INTERFACE ?? "uagv" },
            manufacturer: { type: "string", default: process.env.VDA5050_MANUFACTURER },
            visualization: { type: "boolean", default: false },
        },
    });
    if (!values.manufacturer) {
        throw new Error("--manufacturer (or VDA5050_MANUFACTURER) is required");
    }
    return values;
}

function orderHandlers(agvId) {
    const about = (context) => ({
        ...agvId, orderId: context.order.orderId, orderUpdateId: context.order.orderUpdateId,
    });
    return {
        onOrderProcessed: guard("onOrderProcessed", (withError, byCancelation, active, context) =>
            emit("orderProcessed", { ...about(context), error: withError ?? null, byCancelation, active })),
        onNodeTraversed: guard("onNodeTraversed", (node, nextEdge, nextNode, context) =>
            emit("nodeTraversed", {
                ...about(context), nodeId: node.nodeId, sequenceId: node.sequenceId,
                nextEdgeId: nextEdge?.edgeId ?? null, nextNodeId: nextNode?.nodeId ?? null,
            })),
        onEdgeTraversing: guard("onEdgeTraversing", (edge, start, end, changes, invocation, context) =>
            emit("edgeTraversing", {
                ...about(context), edgeId: edge.edgeId, sequenceId: edge.sequenceId, changes, invocation,
            })),
        onEdgeTraversed: guard("onEdgeTraversed", (edge, start, end, context) =>
            emit("edgeTraversed", { ...about(context), edgeId: edge.edgeId, sequenceId: edge.sequenceId })),
        onActionStateChanged: guard("onActionStateChanged", (actionState, withError, action, target, context) =>
            emit("actionStateChanged", {
                ...about(context), actionId: action.actionId, actionType: action.actionType,
                actionStatus: actionState.actionStatus, resultDescription: actionState.resultDescription ?? null,
                error: withError ?? null,
                target: "nodeId" in target ? { nodeId: target.nodeId } : { edgeId: target.edgeId },
                sequenceId: target.sequenceId,
            })),
    };
}

function instantActionHandlers() {
    return {
        onActionStateChanged: guard("onActionStateChanged", (actionState, withError, action, agvId) =>
            emit("instantActionStateChanged", {
                ...agvId, actionId: action.actionId, actionType: action.actionType,
                actionStatus: actionState.actionStatus, error: withError ?? null,
            })),
        onActionError: guard("onActionError", (error, action, agvId) =>
            emit("instantActionError", { ...agvId, actionId: action.actionId, actionType: action.actionType, error })),
    };
}

async function run(controller, command, config) {
    const agvId = {
        manufacturer: command.manufacturer ?? config.manufacturer,
        serialNumber: command.serialNumber,
    };
    const id = command.id ?? null;
    switch (command.cmd) {
        case "track": {
            const tracked = controller.getTrackedState(agvId);
            emit("tracked", {
                id, ...agvId, connectionState: tracked?.state ?? null, timestamp: tracked?.timestamp ?? null,
            });
            return;
        }
        case "order": {
            const sent = await controller.assignOrder(agvId, command.order, orderHandlers(agvId));
            if (sent === undefined) {
                emit("orderDiscarded", { id, ...agvId, orderId: command.order.orderId, orderUpdateId: command.order.orderUpdateId });
            } else {
                emit("orderAssigned", { id, ...agvId, orderId: sent.orderId, orderUpdateId: sent.orderUpdateId, headerId: sent.headerId });
            }
            return;
        }
        case "instantActions": {
            // the library's 2.0 object names the array `instantActions` (the 2.0 text: `actions`)
            const actions = command.actions ?? command.instantActions;
            const sent = await controller.initiateInstantActions(agvId, { instantActions: actions }, instantActionHandlers());
            emit("instantActionsSent", {
                id, ...agvId, headerId: sent.headerId, actionIds: actions.map((action) => action.actionId),
            });
            return;
        }
        case "quit":
            await quit(controller, 0);
            return;
        default:
            throw new Error(`unknown cmd ${JSON.stringify(command.cmd)}`);
    }
}

let quitting = false;

async function quit(controller, code) {
    if (quitting) {
        return;
    }
    quitting = true;
    try {
        await controller?.stop();
        emit("stopped", { code });
    } catch (error) {
        emit("fatal", { message: `stop failed: ${describe(error)}` });
        code = code || 1;
    }
    process.exit(code);
}

async function main() {
    let config;
    let controller;
    try {
        config = options();
        const brokerUrl = `mqtt://${config.host}:${config.port}`;
        controller = new MasterController(
            { interfaceName: config.interface, transport: { brokerUrl }, vdaVersion: VDA_VERSION },
            { targetAgvs: { manufacturer: config.manufacturer } },
        );
        controller.registerConnectionStateChange(guard("connectionStateChange", (state, previous) =>
            emit("client", { state, previous: previous ?? null })));
        controller.trackAgvs(guard("trackAgvs", (agvId, connectionState, timestamp) =>
            emit("connection", { ...agvId, connectionState, timestamp })));
        await controller.start(); // subscribes connection (all AGVs) and state (targetAgvs)
        const mine = { manufacturer: config.manufacturer };
        await controller.subscribe(Topic.State, mine, guard("state", (state, agvId) => emit("state", { ...agvId, state })));
        await controller.subscribe(Topic.Factsheet, mine, guard("factsheet", (factsheet, agvId) =>
            emit("factsheet", { ...agvId, factsheet })));
        if (config.visualization) {
            await controller.subscribe(Topic.Visualization, mine, guard("visualization", (visualization, agvId) =>
                emit("visualization", { ...agvId, visualization })));
        }
        emit("ready", {
            brokerUrl, interfaceName: config.interface, manufacturer: config.manufacturer,
            vdaVersion: VDA_VERSION, clientId: controller.clientId,
        });
    } catch (error) {
        emit("fatal", { message: describe(error) });
        process.exit(1);
    }

    // Commands run one after another, in the order given: an order update must follow its order.
    let queue = Promise.resolve();
    const lines = createInterface({ input: process.stdin, crlfDelay: Infinity });
    lines.on("line", (line) => {
        if (line.trim() === "") {
            return;
        }
        queue = queue.then(async () => {
            let command;
            try {
                command = JSON.parse(line);
                await run(controller, command, config);
            } catch (error) {
                emit("commandError", { id: command?.id ?? null, cmd: command?.cmd ?? null, message: describe(error), line });
            }
        });
    });
    lines.on("close", () => {
        queue = queue.then(() => quit(controller, 0));
    });
}

main();
